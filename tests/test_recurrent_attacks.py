"""Every attack column plays a recurrent (LSTM) victim with the memory it carries.

A white-box attack computes the perturbation of step t with the victim's memory at t (before
the victim acts on it), as ATLA's attacks do; the victim's memory then advances on the
perturbed observation. What attacks learn per victim (Robust Sarsa's critic, PA-AD's
director) is learned on episodes that reset and advance that memory, and cached under a key
that probes it. The end-to-end tests play every column against a recurrent protagonist.
"""

from __future__ import annotations

import copy
import csv
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch

import advgame
from advgame.adversaries import MADAttack
from advgame.adversaries.sarsa_critic import collect, probe_observations
from advgame.adversaries.whitebox import victim_fingerprint
from advgame.agents.common.checkpoint import SB3Checkpoint
from advgame.agents.common.recurrent_policy import RecurrentSB3Policy
from advgame.cli import main
from advgame.core.episodes import build_policies, reseed_policies
from advgame.core.views import SingleAgentView
from advgame.disruptors import ObservationDisruptor
from advgame.evaluation import AdversarySetup, evaluate, population_jobs

pytestmark = pytest.mark.usefixtures("one_torch_thread")
ADV = "observation_adversary"
ENV = "InvertedPendulum-v5"


def _memory_model(forgetful: bool = False) -> Any:
    """A RecurrentPPO on InvertedPendulum whose action depends on the episode's first observation.

    LSTM unit 0 records the sign of the first cart position (its input gate closes once unit 1,
    a flag, is on); unit 2 reads the pole angle and unit 3 the cart velocity, and the memory
    opens the output gate of one of them: with a positive memory the action is about
    ``tanh(5 * angle)``, with a negative one ``tanh(5 * velocity)``, and the other reading has
    exactly zero gradient. `forgetful`: no recurrent weights, so it acts alike at the first
    step of an episode but never remembers.
    """
    import gymnasium as gym
    from sb3_contrib import RecurrentPPO

    model = RecurrentPPO(
        "MlpLstmPolicy", gym.make(ENV), seed=0, device="cpu",
        policy_kwargs={"lstm_hidden_size": 4, "net_arch": []},
    )  # fmt: skip
    policy, lstm = model.policy, model.policy.lstm_actor
    with torch.no_grad():
        for p in (*lstm.parameters(), *policy.action_net.parameters(), policy.log_std):
            p.zero_()
        w_ih, w_hh, b = lstm.weight_ih_l0, lstm.weight_hh_l0, lstm.bias_ih_l0
        i, f, g, o = 0, 4, 8, 12  # PyTorch's gate rows: input, forget, cell, output
        b[i : i + 4] = 20.0  # input gates open ...
        w_hh[i, 1] = -400.0  # ... unit 0's only until the flag is on
        b[f : f + 2], b[f + 2 : f + 4] = 20.0, -20.0  # units 0, 1 keep their cell; 2, 3 do not
        w_ih[g, 0] = 1e4  # unit 0: the sign of the cart position
        b[g + 1] = 20.0  # unit 1: the flag
        w_ih[g + 2, 1], w_ih[g + 3, 2] = 5.0, 5.0  # unit 2: the angle; unit 3: the velocity
        b[o : o + 2] = 20.0
        w_hh[o + 2, 0], w_hh[o + 3, 0] = 200.0, -200.0  # the memory picks the reading
        policy.action_net.weight[0, 2:] = 1.0
        if forgetful:
            w_hh.zero_()
    return model


def _victim(forgetful: bool = False) -> RecurrentSB3Policy:
    return RecurrentSB3Policy(_memory_model(forgetful))


def _lstm(policy: Any, x: torch.Tensor, h: torch.Tensor, c: torch.Tensor) -> tuple[Any, Any]:
    """One LSTM step written out: the victim's actor memory after it reads `x`."""
    lstm = policy.lstm_actor
    gates = x @ lstm.weight_ih_l0.T + lstm.bias_ih_l0 + h @ lstm.weight_hh_l0.T + lstm.bias_hh_l0
    i, f, g, o = gates.chunk(4, dim=-1)
    c = torch.sigmoid(f) * c + torch.sigmoid(i) * torch.tanh(g)
    return torch.sigmoid(o) * torch.tanh(c), c


def _mad_by_hand(
    policy: Any, clean: np.ndarray, state: tuple[Any, Any], rng: np.random.Generator, steps: int,
    scale: np.ndarray,
) -> np.ndarray:  # fmt: skip
    """MAD's walk (random start, signed steps of 2.5 / steps, best iterate) from `state`."""
    h, c = state[0][0], state[1][0]
    x = torch.as_tensor(clean, dtype=torch.float32)[None]
    scale_t = torch.as_tensor(scale, dtype=torch.float32)

    def mean(obs: torch.Tensor) -> torch.Tensor:
        return policy.action_net(_lstm(policy, obs, h, c)[0])

    with torch.no_grad():
        reference = mean(x)
    u = np.clip(rng.uniform(-1.0, 1.0, (1, len(clean))), -1.0, 1.0)
    best, best_u = -np.inf, u
    for step in range(steps + 1):
        u_t = torch.as_tensor(u, dtype=torch.float32).requires_grad_(True)
        score = ((mean(x + scale_t * u_t) - reference) ** 2).sum() / 2.0  # std 1
        if float(score.detach()) > best:
            best, best_u = float(score.detach()), u
        if step == steps:
            break
        (grad,) = torch.autograd.grad(score, u_t)
        u = np.clip(u + 2.5 / steps * np.sign(grad.numpy()), -1.0, 1.0)
    return best_u[0].astype(np.float32)


def test_mad_walks_with_the_carried_memory_and_the_memory_moves_on_the_perturbed_obs() -> None:
    victim = _victim()
    game = advgame.make(ENV, disruptors=[ObservationDisruptor(eps=0.05)])
    pols = build_policies(game, {"protagonist": victim, ADV: MADAttack(steps=5)})
    attack, policy = pols[ADV], victim.model.policy
    reseed_policies(pols, 3)
    game.reset(seed=3)
    scale = attack.disruptor.unit.astype(np.float32)
    zero = (torch.zeros(1, 1, 4), torch.zeros(1, 1, 4))
    for t in range(4):
        assert game.move == "sense"
        state = victim.hidden_state()["actor"]
        clean = np.asarray(game.true_observation("protagonist"), dtype=np.float32)
        rng = copy.deepcopy(attack.rng)
        with_memory = _mad_by_hand(policy, clean, state, copy.deepcopy(rng), 5, scale)
        memoryless = _mad_by_hand(policy, clean, zero, rng, 5, scale)
        u = attack.act(game.observe(ADV))
        np.testing.assert_allclose(u, with_memory, atol=1e-6)
        if t == 0:  # a fresh episode: the carried memory is the zero one
            np.testing.assert_allclose(u, memoryless, atol=1e-6)
        else:  # the memory picked one reading: the other one's coordinate stays where it began
            assert np.abs(u - memoryless).max() > 1e-2
            # (as do the position's and the pole rate's: zero gradient with this memory)
            assert np.sum(np.abs(u) < 1.0 - 1e-6) >= 3
        game.play({ADV: u})
        shown = np.asarray(game.observe("protagonist"), dtype=np.float32)
        np.testing.assert_allclose(shown, clean + scale * u, atol=1e-6)
        game.play({"protagonist": victim.act(shown)})
        h, c = _lstm(policy, torch.as_tensor(shown)[None], state[0][0], state[1][0])
        after = victim.hidden_state()["actor"]
        torch.testing.assert_close(after[0][0], h.detach(), atol=1e-6, rtol=0)
        torch.testing.assert_close(after[1][0], c.detach(), atol=1e-6, rtol=0)
    game.close()


def test_the_cache_key_probes_the_memory_and_leaves_it_alone() -> None:
    victim, forgetful = _victim(), _victim(forgetful=True)
    probes = probe_observations(4)
    with torch.no_grad():  # from a zero memory, one step each: the two act alike
        assert torch.equal(victim.action_mean(probes), forgetful.action_mean(probes))
    first = victim_fingerprint(victim, 4)
    for obs in np.random.default_rng(0).uniform(-0.1, 0.1, (5, 4)):
        victim.act(obs)
    carried = victim.hidden_state()
    assert victim_fingerprint(victim, 4) == first  # wherever in an episode it is asked
    after = victim.hidden_state()
    for head in ("actor", "critic"):
        assert all(torch.equal(a, b) for a, b in zip(after[head], carried[head], strict=True))
    assert first[0] == b"recurrent"  # never a feed-forward policy's key
    assert victim_fingerprint(forgetful, 4) != first  # the memory is part of the key


class _Spy(RecurrentSB3Policy):
    """Counts its resets."""

    def __init__(self, model: Any) -> None:
        super().__init__(model)
        self.resets = 0

    def reset(self, seed: int | None = None) -> None:
        super().reset(seed)
        self.resets += 1


def test_robust_sarsa_data_plays_the_victim_with_its_memory_per_episode() -> None:
    model = _memory_model()
    with torch.no_grad():
        model.policy.action_net.bias[0] = 2.0  # a push on top: the pole falls within a few steps
    spy = _Spy(model)
    for obs in np.random.default_rng(1).uniform(-0.1, 0.1, (7, 4)):  # a stale memory to drop
        spy.act(obs)
    data = collect(ENV, "protagonist", spy, samples=40, seed=0)
    ends = np.flatnonzero(data["done"])
    assert len(ends) >= 3 and spy.resets == len(ends) + 1  # short episodes, one reset each
    replay = RecurrentSB3Policy(model)  # the same net with its own memory
    for k, obs in enumerate(data["obs"]):
        if k == 0 or data["done"][k - 1]:
            replay.reset()
        with torch.no_grad():
            np.testing.assert_array_equal(
                data["act"][k], replay.action_mean(torch.as_tensor(obs[None]))[0]
            )
            replay.act(obs)
            successor = replay.action_mean(torch.as_tensor(data["next"][k][None]))[0]
        np.testing.assert_array_equal(data["next_act"][k], successor)


def test_training_views_reset_the_victims_memory_and_advance_it_on_what_it_was_shown() -> None:
    """What PA-AD's director and the learned (optimal) adversaries train in."""
    victim = _victim()
    game = advgame.make(ENV, disruptors=[ObservationDisruptor(eps=0.05)])
    view = SingleAgentView(game, ADV, {"protagonist": victim})
    u = np.full(4, 0.5, dtype=np.float32)
    for seed in (0, 1):
        true_obs, _ = view.reset(seed=seed)
        assert all(not s.any() for s in victim.hidden_state()["actor"])  # a fresh memory
        done = False
        while not done:
            h, c = victim.hidden_state()["actor"]
            shown = torch.as_tensor(np.asarray(true_obs, np.float32) + np.float32(0.05) * u)
            true_obs, _, terminated, truncated, _ = view.step(u)
            done = terminated or truncated
            expect = _lstm(victim.model.policy, shown[None], h[0], c[0])
            after = victim.hidden_state()["actor"]
            torch.testing.assert_close(after[0][0], expect[0].detach(), atol=1e-6, rtol=0)
        assert any(s.any() for s in victim.hidden_state()["actor"])  # it remembered the episode
    game.close()


def test_a_stale_attack_cannot_play_a_recurrent_row_and_says_why(tmp_path: Path) -> None:
    """A stale attack moves with the victim: the memory it would read depends on who goes first."""
    _memory_model().save(tmp_path / "lstm.zip")
    prots = {"lstm": SB3Checkpoint(str(tmp_path / "lstm.zip"), "recurrent-ppo")}
    setups = {
        name: AdversarySetup(
            {"disruptors": [ObservationDisruptor(eps=0.05, timing=timing)]},
            {ADV: MADAttack(steps=2)},
        )
        for name, timing in (("stale mad", "stale"), ("mad", "sense"))
    }
    table = evaluate(population_jobs(ENV, prots, setups, seeds=(0,)), progress=False)
    assert list(table.not_applicable) == [("lstm", "stale mad")]
    reason = table.not_applicable[("lstm", "stale mad")]
    assert "recurrent" in reason and "timing='sense'" in reason
    assert [r["adversary"] for r in table.rows] == ["mad"]


def test_games_in_lockstep_attack_each_victim_with_its_own_memory(tmp_path: Path) -> None:
    """The batched evaluation path plays every game's own victim: rows as the lone games'."""
    import gymnasium as gym
    from sb3_contrib import RecurrentPPO

    from advgame.evaluation.table.batched import play_job, play_job_sequential

    kwargs = {"lstm_hidden_size": 8, "net_arch": []}
    model = RecurrentPPO("MlpLstmPolicy", gym.make("Hopper-v5"), seed=0, policy_kwargs=kwargs)
    model.save(tmp_path / "lstm.zip")
    prots = {"lstm": SB3Checkpoint(str(tmp_path / "lstm.zip"), "recurrent-ppo")}
    mad = AdversarySetup({"preset": "default"}, {ADV: MADAttack(steps=2)})
    [job] = population_jobs("Hopper-v5", prots, {"mad": mad}, seeds=(0, 1, 2))
    key = ("seed", "true_return", "length")
    lockstep = [tuple(r[k] for k in key) for r in play_job(job)]
    assert lockstep == [tuple(r[k] for k in key) for r in play_job_sequential(job)]
    assert len({r[1] for r in lockstep}) == 3  # three different episodes


@pytest.fixture(scope="module")
def lstm_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A tiny ATLA-LSTM run on Hopper-v5: a recurrent protagonist and its learned adversary."""
    run = tmp_path_factory.mktemp("atla-lstm") / "run"
    hp = '{"n_steps": 64, "batch_size": 32}'
    args = ["train", "--method", "atla-lstm", "--scenario", "Hopper-v5", "--iterations", "1"]
    args += ["--protagonist-steps", "64", "--adversary-steps", "64", "--eval-episodes", "1"]
    args += ["--set", f"protagonist_hparams={hp}", "--set", f"adversary_hparams={hp}"]
    assert main([*args, "--run-dir", str(run), "--no-progress"]) == 0
    return run


def _returns(out: Path) -> dict[str, list[float]]:
    with (out / "payoff.csv").open(newline="") as f:
        rows = list(csv.DictReader(f))
    assert all(r["clipped"] == "0" for r in rows)  # every attack stayed in its budget
    table: dict[str, list[float]] = {}
    for r in sorted(rows, key=lambda r: int(r["seed"])):
        table.setdefault(r["adversary"], []).append(float(r["true_return"]))
    return table


def test_every_attack_column_plays_a_recurrent_protagonist_from_the_cli(
    lstm_run: Path, tmp_path: Path
) -> None:
    out = tmp_path / "res"
    columns = ["nominal", "attack:random", "attack:mad", "attack:critic"]
    columns += ["attack:rs,samples=128,epochs=1", "attack:pa-ad,samples=64", "learned"]
    args = ["evaluate", str(lstm_run), "--adversaries", *columns, "--seeds", "1", "--budgets"]
    assert main([*args, "--out", str(out), "--workers", "1"]) == 0
    returns = _returns(out)
    attacks = ["random", "mad", "critic", "rs", "pa-ad"]
    assert set(returns) == {
        "nominal",
        *(f"attack {a}" for a in attacks),
        f"learned ({lstm_run.name})",
    }
    assert all(len(v) == 1 for v in returns.values())  # no cell n/a
    for name, values in returns.items():  # Hopper is chaotic: any perturbation moves the return
        if name != "nominal":
            assert values != returns["nominal"], name
    assert "n/a" not in (out / "report.md").read_text()


def test_the_searched_optimal_attack_trains_against_a_recurrent_protagonist(
    lstm_run: Path, tmp_path: Path
) -> None:
    from sb3_contrib import RecurrentPPO

    from advgame.evaluation.attacks.optimal import OPTIMAL, OptimalSearch, optimal_jobs
    from advgame.evaluation.table.protagonists import run_protagonist

    cfg, spec = run_protagonist(lstm_run)
    assert spec.algo == "recurrent-ppo"
    small = {"n_steps": 64, "batch_size": 32}
    lstm = {**small, "lstm_hidden_size": 8, "algo": "recurrent-ppo", "victims": "recurrent"}
    search = OptimalSearch(steps=64, grid=(small, lstm), select_seeds=1)
    mlp = SB3Checkpoint(str(lstm_run / "no-such-model.zip"), "ppo", None)  # never trained on
    jobs = optimal_jobs(
        "Hopper-v5", cfg.preset, ADV, {"lstm": spec}, search, tmp_path, seeds=(0, 1)
    )
    table = evaluate(jobs, progress=False)
    rows = [r for r in table.rows if r["adversary"] == OPTIMAL]
    assert len(rows) == 2 and all(r["clipped"] == 0 and r["length"] > 0 for r in rows)
    assert list((tmp_path / "optimal" / "lstm" / "0").glob("*.zip"))
    # the LSTM candidate, as ATLA attacks its LSTM agents: a RecurrentPPO adversary
    (adversary,) = (tmp_path / "optimal" / "lstm" / "1").glob("*.zip")
    assert RecurrentPPO.load(adversary, device="cpu").policy.lstm_hidden_state_shape[-1] == 8
    found = json.loads((tmp_path / "optimal.json").read_text())["lstm"]["candidates"]
    assert [c["hparams"].get("algo", "ppo") for c in found] == ["ppo", "recurrent-ppo"]
    # a protagonist without memory is not offered the LSTM candidate
    from advgame.evaluation.attacks.optimal import _applies

    assert _applies(lstm, spec) and not _applies(lstm, mlp) and _applies(small, mlp)


def test_max_cost_plays_a_recurrent_protagonist_on_a_safe_task(tmp_path: Path) -> None:
    from sb3_contrib import RecurrentPPO

    from advgame.adversaries import MaxCostAttack
    from advgame.core.episodes import rollout

    game = advgame.make("SafetyHopper-v5", preset="default", max_episode_steps=30)
    env = SingleAgentView(game, "protagonist")  # an env with the protagonist's spaces
    model = RecurrentPPO(
        "MlpLstmPolicy", env, seed=0, device="cpu", policy_kwargs={"lstm_hidden_size": 8}
    )
    attack = MaxCostAttack(samples=64, epochs=1, cache_dir=str(tmp_path))
    victim = RecurrentSB3Policy(model)
    [result] = rollout(game, {"protagonist": victim, ADV: attack}, seed=0)
    assert result.length > 0 and result.clipped[ADV] == 0
    assert len(list(tmp_path.glob("*.pt"))) == 1  # its cost critic, learned once
    game.close()


def test_the_attack_benchmark_times_a_recurrent_victim(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[1] / "benchmarks"))
    import importlib

    bench = importlib.import_module("bench_attack")
    bench.main(["--smoke", "--victims", "lstm"])
    printed = capsys.readouterr().out
    assert "RecurrentPPO (64 LSTM units)" in printed
    ratio = next(line for line in printed.splitlines() if line.startswith("lstm mad"))
    assert 0 < float(ratio.split()[-1]) < 1  # the attacked path is timed, and slower
    assert "goal lstm mad / nominal >= 0.25" in printed
