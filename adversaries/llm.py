"""The LLM adversary: a language model as a bounded, validated adversary policy.

The paper prompts a model with the task, the state, the reward and a noise region and feeds
the reply string straight into the observation. Here the model is an ordinary adversary
policy (`LLMAdversary.build(info) -> Policy`), interchangeable with noise, schedules, networks
and populations, and its replies are untrusted input: every reply is parsed
(`llm_reply.parse_reply`), checked for length and finiteness, projected into the budget and
counted; anything malformed plays the configured fallback instead. It calls the model only on
the steps its disruptor's `Schedule` makes it move (every step, every 100 steps, ...).

Example:
    >>> import advgame
    >>> from advgame import ObservationDisruptor, Schedule
    >>> game = advgame.make("Hopper-v5", disruptors=[
    ...     ObservationDisruptor(eps=0.8, schedule=Schedule.every_n(100))])
    >>> spec = LLMAdversary(region=(0.2, 0.8), task="Hopper-v5: hop forward")
    >>> spec.kind_of(game.agent_info("observation_adversary"))
    'observation'

"""

from __future__ import annotations

import importlib.resources
import json
import logging
import time
from collections import Counter, OrderedDict, deque
from collections.abc import Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from string import Template
from typing import Any, Literal

import numpy as np

from advgame.adversaries.llm_backends import BackendError, LocalModel, OpenAIEndpoint
from advgame.adversaries.llm_reply import Reply, parse_reply, reply_schema
from advgame.core.policy import AgentInfo
from advgame.errors import BudgetError, ConfigError, did_you_mean

__all__ = ["KINDS", "LLMAdversary", "LLMPolicy", "template_text"]

log = logging.getLogger(__name__)

KINDS = ("observation", "action", "reward", "dynamics")
"""Prompt template per disruptor kind (cost uses reward's; force uses dynamics')."""
_KIND_OF = {"cost": "reward", "force": "dynamics"}


def template_text(kind: str) -> str:
    """The packaged prompt template for `kind` (copy it, edit it, pass it as `template`)."""
    if kind not in KINDS:
        raise ConfigError(f"Unknown prompt kind {kind!r}.{did_you_mean(kind, KINDS)}")
    return (
        importlib.resources.files("advgame.adversaries") / "prompts" / f"{kind}.txt"
    ).read_text()


@dataclass(frozen=True)
class LLMAdversary:
    """A language model that chooses the perturbation, bounded and validated.

    On each move the model gets the task, the true state, the budget region and its own recent
    perturbations, and answers ``{"values": [...]}``: the perturbation in the disruptor's raw
    units (a state offset, an action offset, a parameter value). The reply is projected into
    ``region`` ∩ the disruptor's budget; malformed replies and backend failures play `fallback`.
    """

    backend: LocalModel | OpenAIEndpoint = field(default_factory=LocalModel)
    """Where replies come from: the offline local model (default) or an OpenAI-compatible URL."""
    region: tuple[float | Sequence[float], float | Sequence[float]] | None = None
    """``(low, high)`` per dimension in raw units, e.g. the paper's C[0.2, 0.8] is
    ``(0.2, 0.8)``; ``None``: the disruptor's whole budget."""
    task: str = "a simulated robot control task (MuJoCo)"
    """What the protagonist is doing, in words, for the prompt."""
    template: str | None = None
    """A prompt template file (``string.Template``: ``$state``, ``$rewards``, ``$low``, ...); ``None``: the
    packaged one for the disruptor's kind (see `template_text`)."""
    fallback: Literal["noop", "random"] = "noop"
    """What a rejected reply or a failed call plays: the no-op, or uniform in the region."""
    mode: Literal["sync", "async"] = "sync"
    """``"sync"``: wait for each reply (reproducible). ``"async"``: never block the simulator;
    play the last applied perturbation, across episodes (the fallback before the first reply),
    while a call is pending, and apply the reply on the first move after it arrives."""
    history: int = 3
    """How many of its own recent perturbations the prompt shows."""
    digits: int = 3
    """Decimals of the numbers in the prompt."""
    cache_size: int = 256
    """Replies remembered per identical prompt (0: no cache)."""
    retries: int = 2
    """Extra attempts after a failed call."""
    backoff_s: float = 0.5
    """Wait before retry ``i`` is ``backoff_s * 2**i`` seconds."""
    max_reply_chars: int = 4000
    """Longer replies are rejected unread."""
    transcript: str | None = None
    """A JSON-lines file that gets one line per call (prompt, reply, status, what was applied)."""
    schema: bool = True
    """Ask for a schema-constrained reply; ``False``: the plain prompt alone (fallback parse)."""

    def __post_init__(self) -> None:
        if self.fallback not in ("noop", "random"):
            raise ConfigError(f"fallback must be 'noop' or 'random', got {self.fallback!r}.")
        if self.mode not in ("sync", "async"):
            raise ConfigError(f"mode must be 'sync' or 'async', got {self.mode!r}.")
        if not isinstance(self.backend, LocalModel | OpenAIEndpoint):
            raise ConfigError(
                f"backend must be LocalModel() or OpenAIEndpoint(...), got {self.backend!r}."
            )
        ints = (self.history, self.digits, self.cache_size, self.retries)
        if min(ints) < 0 or self.backoff_s < 0 or self.max_reply_chars < 16:
            raise ConfigError(
                "LLMAdversary needs history, digits, cache_size, retries, backoff_s >= 0 and "
                f"max_reply_chars >= 16, got {(*ints, self.backoff_s, self.max_reply_chars)}."
            )
        if self.template is not None and not Path(self.template).is_file():
            raise ConfigError(
                f"LLMAdversary.template {self.template!r} is not a file; copy one of "
                f"{list(KINDS)} with template_text(kind) and point to the copy."
            )

    @staticmethod
    def kind_of(info: AgentInfo) -> str:
        """The prompt kind of `info`'s disruptor."""
        if info.disruptor is None:
            raise ConfigError(
                f"{info.agent!r} is a protagonist; an LLMAdversary needs an adversary."
            )
        kind = str(info.disruptor.spec.kind)
        return _KIND_OF.get(kind, kind)

    def build(self, info: AgentInfo) -> LLMPolicy:
        """The policy for `info`'s disruptor (the backend connects at its first call)."""
        kind = self.kind_of(info)
        if isinstance(self.backend, LocalModel):
            self.backend.check()
        text = Path(self.template).read_text() if self.template else template_text(kind)
        low, high = _region(info, self.region)
        return LLMPolicy(self, info, Template(text), low, high, _labels(info, kind))


def _budget_box(info: AgentInfo) -> tuple[np.ndarray, np.ndarray]:
    """The disruptor's budget in raw units (what encodes into the ``[-1, 1]`` action box)."""
    d = info.disruptor
    if d is not None and not getattr(d, "bounded", True):
        n = info.action_size
        return np.full(n, -np.inf), np.full(n, np.inf)
    unit = getattr(d, "unit", None)
    if unit is not None:
        return -np.asarray(unit, np.float64), np.asarray(unit, np.float64)
    low, high = getattr(d, "low", None), getattr(d, "high", None)
    if low is not None and high is not None:
        return np.asarray(low, np.float64), np.asarray(high, np.float64)
    n = info.action_size
    return -np.ones(n), np.ones(n)


def _region(info: AgentInfo, region: Any) -> tuple[np.ndarray, np.ndarray]:
    """``region`` ∩ the budget, per dimension; an error if it is empty or unbounded."""
    n = info.action_size
    low, high = _budget_box(info)
    if region is not None:
        try:
            r_low = np.broadcast_to(np.asarray(region[0], np.float64), (n,))
            r_high = np.broadcast_to(np.asarray(region[1], np.float64), (n,))
        except (ValueError, TypeError, IndexError):
            raise ConfigError(
                f"region must be (low, high), each a number or {n} numbers, got {region!r}."
            ) from None
        low, high = np.maximum(low, r_low), np.minimum(high, r_high)
    if not (np.all(np.isfinite(low)) and np.all(np.isfinite(high))) or np.any(low > high):
        raise BudgetError(
            f"The LLM adversary of {info.agent!r} needs a finite, non-empty region inside its "
            f"budget; got low={low}, high={high}. Give region=(low, high) in raw units inside "
            "the disruptor's budget (an unbounded disruptor always needs one)."
        )
    return low, high


def _labels(info: AgentInfo, kind: str) -> str:
    spec = info.disruptor.spec if info.disruptor is not None else None
    params = getattr(spec, "params", None)
    if kind == "dynamics" and params:
        return ", ".join(f"{p.kind}{list(p.names) if p.names else ''}" for p in params)
    dims = getattr(spec, "dims", None)
    if kind == "observation" and dims is not None:
        return "state dimensions " + ", ".join(str(int(i)) for i in dims)
    return f"values 0..{info.action_size - 1} in order"


class LLMPolicy:
    """The built LLM adversary: prompt, call (cached, retried, maybe async), validate, project."""

    def __init__(
        self,
        spec: LLMAdversary,
        info: AgentInfo,
        template: Template,
        low: np.ndarray,
        high: np.ndarray,
        labels: str,
    ) -> None:
        self.spec, self.info, self.template = spec, info, template
        self.low, self.high, self.labels = low, high, labels
        self.size = info.action_size
        self.schema = reply_schema(self.size) if spec.schema else None
        self.counters: Counter[str] = Counter()
        """calls, cached, errors, fallbacks, the status of each reply, clipped_values."""
        self.rng = np.random.default_rng()
        self._client: Any = None
        self._cache: OrderedDict[str, str] = OrderedDict()
        self._recent: deque[list[float]] = deque(maxlen=max(spec.history, 1))
        self._pool: ThreadPoolExecutor | None = None
        self._pending: Future | None = None
        self._current: np.ndarray | None = None
        self.episode, self.step = -1, 0
        self.game: Any = None
        """The game played (`attach`): the prompt reports its true rewards."""

    def __getstate__(self) -> dict[str, Any]:
        """Pickle the configuration and counters; connections and threads are rebuilt."""
        state = dict(self.__dict__)
        state.update(_client=None, _pool=None, _pending=None)
        return state

    def reset(self, seed: int | None = None) -> None:
        """Start an episode: reseed the fallback's generator, forget recent perturbations."""
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        self._recent.clear()
        if self.spec.mode == "sync":
            self._current = None  # async keeps playing its last reply across episodes
        self.episode, self.step = self.episode + 1, 0

    def attach(self, game: Any, victims: Any) -> None:
        """Remember the game (`advgame.core.episodes.build_policies` calls this): its true rewards."""
        self.game = game

    def prompt(self, observation: Any) -> str:
        """The prompt for the true state `observation`."""
        d = self.spec.digits
        state = np.asarray(observation, dtype=np.float64).ravel()
        fmt = _fmt(d)
        history = "; ".join(fmt(v) for v in self._recent) if self.spec.history else ""
        rewards = "unknown"
        if self.game is not None:
            last, total = self.game.last_reward, self.game.episode_reward
            rewards = f"{last:.{d}g} at the last step, {total:.{d}g} so far this episode"
        return self.template.safe_substitute(
            rewards=rewards,
            task=self.spec.task,
            state=fmt(state),
            state_size=state.size,
            size=self.size,
            labels=self.labels,
            low=_bound(self.low, d),
            high=_bound(self.high, d),
            history=history or "none yet",
        )

    def act(self, observation: Any) -> np.ndarray:
        """The encoded perturbation for this move (the fallback when the reply is unusable)."""
        self.step += 1
        prompt = self.prompt(observation)
        if self.spec.mode == "async":
            return self._act_async(prompt)
        return self._apply(prompt, *self._ask(prompt))

    def _act_async(self, prompt: str) -> np.ndarray:
        pending = self._pending
        if pending is not None and pending.done():
            self._pending = None
            ask_prompt, text, latency, cached = pending.result()
            self._current = self._apply(ask_prompt, text, latency, cached)
        if self._pending is None:
            if self._pool is None:
                self._pool = ThreadPoolExecutor(1, thread_name_prefix="llm-adversary")
            self._pending = self._pool.submit(lambda: (prompt, *self._ask(prompt)))
        if self._current is None:
            self.counters["pending"] += 1
            return self._fallback()[0]
        return self._current

    def _ask(self, prompt: str) -> tuple[str | None, float, bool]:
        """The reply text (``None`` after all retries failed), its latency and cache flag."""
        self.counters["calls"] += 1
        if prompt in self._cache:
            self._cache.move_to_end(prompt)
            self.counters["cached"] += 1
            return self._cache[prompt], 0.0, True
        start = time.perf_counter()
        text = self._call(prompt)
        latency = time.perf_counter() - start
        if text is not None and self.spec.cache_size:
            self._cache[prompt] = text
            if len(self._cache) > self.spec.cache_size:
                self._cache.popitem(last=False)
        return text, latency, False

    def _call(self, prompt: str) -> str | None:
        messages = [{"role": "user", "content": prompt}]
        for attempt in range(self.spec.retries + 1):
            try:
                if self._client is None:
                    self._client = self.spec.backend.connect()
                return str(self._client.complete(messages, self.schema))
            except BackendError as e:
                self.counters["errors"] += 1
                log.warning("LLM adversary call %d failed: %s", attempt + 1, e)
                if attempt < self.spec.retries:
                    time.sleep(self.spec.backoff_s * 2**attempt)
        return None

    def _apply(self, prompt: str, text: str | None, latency: float, cached: bool) -> np.ndarray:
        reply = (
            Reply("backend_error")
            if text is None
            else parse_reply(text, self.size, self.low, self.high, self.spec.max_reply_chars)
        )
        self.counters[reply.status] += 1
        self.counters["clipped_values"] += reply.clipped
        if reply.values is None:
            self.counters["fallbacks"] += 1
            action, applied = self._fallback()
        else:
            self._recent.append([float(v) for v in reply.values])
            action, applied = self._encode(reply.values), reply.values
        if self.spec.transcript:
            self._write(prompt, text, reply, applied, action, latency, cached)
        return action

    def _encode(self, values: np.ndarray) -> np.ndarray:
        """Raw values -> action, projected into the action box (and counted) once more."""
        u = np.asarray(self.info.encode(values), dtype=np.float32)
        space = self.info.action_space
        low, high = getattr(space, "low", -np.inf), getattr(space, "high", np.inf)
        out = np.clip(u, low, high)
        self.counters["clipped_values"] += int(np.count_nonzero(out != u))
        return out

    def _fallback(self) -> tuple[np.ndarray, np.ndarray | None]:
        """The fallback's action and raw values (``None``: the no-op)."""
        if self.spec.fallback == "random":
            values = self.rng.uniform(self.low, self.high)
            return self._encode(values), values
        return np.asarray(self.info.noop_action, dtype=np.float32), None

    def _write(
        self,
        prompt: str,
        text: str | None,
        reply: Reply,
        applied: np.ndarray | None,
        action: np.ndarray,
        latency: float,
        cached: bool,
    ) -> None:
        """One transcript line: what was asked, answered, and what the disruptor was sent."""
        row = {
            "agent": self.info.agent,
            "episode": self.episode,
            "call": self.step,
            "prompt": prompt,
            "reply": text,
            "status": reply.status,
            "fallback": None if reply.values is not None else self.spec.fallback,
            "applied": None if applied is None else [float(v) for v in applied],
            "action": [float(v) for v in np.ravel(action)],
            "clipped": reply.clipped,
            "latency_s": round(latency, 4),
            "cached": cached,
        }
        path = Path(self.spec.transcript or "")
        path.parent.mkdir(parents=True, exist_ok=True)
        with path.open("a") as f:
            f.write(json.dumps(row) + "\n")

    def close(self) -> None:
        """Stop the async worker thread (the local server stops with the process)."""
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None
            self._pending = None


def _bound(values: np.ndarray, digits: int) -> str:
    """One number when every dimension shares it, else the list."""
    if np.all(values == values[0]):
        return f"{float(values[0]):.{digits}f}"
    return _fmt(digits)(values)


def _fmt(digits: int) -> Any:
    def fmt(values: Any) -> str:
        return "[" + ", ".join(f"{float(v):.{digits}f}" for v in np.ravel(values)) + "]"

    return fmt
