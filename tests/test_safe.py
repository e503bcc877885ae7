"""Safety MuJoCo scenarios and the constrained learners (PPO-Lagrangian, CRPO, PCRPO).

* the cost is computed from the true simulator state: an observation attack leaves it unchanged,
  and it agrees with Gymnasium's own velocity;
* the cost disruptor moves only the observed cost, within its budget, and payoffs stay zero-sum
  on the declared ``reward - w·cost``;
* each learner, on SafetyReacher in a short run, brings the episode cost under its limit while
  its return beats the random policy's (measured in the test);
* a constrained run killed with SIGKILL resumes to the end, its multiplier restored;
* seeded learners reproduce exactly; bad input is a clear error.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch

import advgame
import advgame.cli
import advgame.core.registry
from advgame import ObservationDisruptor, RewardDisruptor
from advgame.agents.safe.ppo import project
from advgame.agents.safe.safe import (
    SAFE_LEARNERS,
    CRPOConfig,
    PCRPOConfig,
    PIDLagConfig,
    PPOLagConfig,
)
from advgame.core.team import team_factory
from advgame.errors import ConfigError, UnknownNameError
from advgame.evaluation import PayoffTable
from advgame.training import learner_config

REACHER = "SafetyReacher-v5"
pytestmark = pytest.mark.usefixtures("one_torch_thread")


def _play(game: advgame.Game, actions: np.ndarray, adversary: Any, seed: int = 0) -> list[dict]:
    """Act moves' protagonist infos (and observations) for a fixed protagonist action sequence."""
    game.reset(seed=seed)
    out, t = [], 0
    while game.agents and t < len(actions):
        move = {a: adversary(game, a) for a in game.agents if a != "protagonist"}
        move["protagonist"] = actions[t]
        seen = game.observe("protagonist")  # what the protagonist acts on, if it acts now
        _, rewards, _, _, infos = game.step(move)
        info = infos["protagonist"]
        if info["acted"]:
            out.append({**info, "obs": seen, "rewards": rewards})
            t += 1
    return out


def _max_push(game: advgame.Game, agent: str) -> np.ndarray:
    return np.full(game.action_space(agent).shape, 1.0, dtype=np.float32)


def test_cost_comes_from_the_true_state_not_the_attacked_observation() -> None:
    actions = np.random.default_rng(0).uniform(-1, 1, (50, 2)).astype(np.float32)
    nominal = advgame.make(REACHER, disruptors=[], threshold=1.0)
    attacked = advgame.make(REACHER, disruptors=[ObservationDisruptor(eps=0.5)], threshold=1.0)
    clean = _play(nominal, actions, _max_push)
    hit = _play(attacked, actions, _max_push)
    costs = [i["true_cost"] for i in clean]
    assert {0.0, 1.0} <= set(costs), "the threshold must make both outcomes happen"
    assert [i["true_cost"] for i in hit] == costs
    assert [i["constraint_value"] for i in hit] == [i["constraint_value"] for i in clean]
    assert any(not np.allclose(a["obs"], b["obs"]) for a, b in zip(hit, clean, strict=True))


def test_velocity_cost_matches_gymnasiums_velocity_and_threshold() -> None:
    game = advgame.make("SafetyHalfCheetah-v5", disruptors=[], threshold=0.3)
    actions = np.random.default_rng(1).uniform(-1, 1, (80, 6)).astype(np.float32)
    infos = _play(game, actions, _max_push)
    for info in infos:
        assert info["constraint_value"] == pytest.approx(info["x_velocity"], abs=1e-9)
        assert info["true_cost"] == float(info["x_velocity"] > 0.3)
    assert 0 < sum(i["true_cost"] for i in infos) < len(infos)


def test_cost_disruptor_moves_only_the_observed_cost_within_its_budget() -> None:
    actions = np.random.default_rng(2).uniform(-1, 1, (50, 2)).astype(np.float32)
    cost = RewardDisruptor(signal="cost", eps=0.3)
    game = advgame.make(REACHER, disruptors=[cost], cost_weight=1.0, threshold=1.0)
    clean = _play(advgame.make(REACHER, disruptors=[], threshold=1.0), actions, _max_push)

    def wild(g: advgame.Game, a: str) -> np.ndarray:  # far outside the budget: clipped
        return np.full(g.action_space(a).shape, 7.0, dtype=np.float32)

    hit = _play(game, actions, wild)
    for a, b in zip(hit, clean, strict=True):
        assert a["true_cost"] == b["true_cost"] and a["true_reward"] == b["true_reward"]
        assert a["cost"] == pytest.approx(a["true_cost"] + 0.3)
        assert a["rewards"]["protagonist"] == pytest.approx(a["true_reward"])
        assert a["payoff"] == pytest.approx(a["true_reward"] - a["true_cost"])
        assert a["rewards"]["cost_adversary"] == pytest.approx(-a["payoff"])


def test_safe_presets_declare_a_cost_weight_and_give_the_papers_settings() -> None:
    presets = advgame.core.registry.scenario_spec("SafetyWalker2d-v5").load_presets()
    names = {"default", "full", "state-gauss-0.3", "action-gauss-0.15", "action-gauss-0.3"}
    assert names | {"cost-gauss-0.15", "cost-gauss-0.3"} <= set(presets)
    assert all(p.cost_weight > 0 for p in presets.values())
    game = advgame.make("SafetyWalker2d-v5", preset="cost-gauss-0.3")
    assert game.cost_weight == presets["cost-gauss-0.3"].cost_weight
    assert game.adversaries == ("cost_adversary",)
    full = advgame.make("SafetyWalker2d-v5", preset="full").adversaries
    assert {"dynamics_adversary", "force_adversary", "cost_adversary"} <= set(full)
    assert len(advgame.list_scenarios(family="safe")) == 9


def test_bad_safe_input_is_a_clear_error() -> None:
    with pytest.raises(UnknownNameError, match="speed"):
        advgame.make(REACHER, constraint="sped")
    with pytest.raises(ConfigError, match="threshold"):
        advgame.make(REACHER, threshold=-1.0)
    with pytest.raises(ConfigError, match="computes no cost"):
        advgame.make("Hopper-v5", cost_weight=1.0)
    with pytest.raises(ConfigError, match="cost_limit"):
        learner_config("crpo", {"cost_limit": -5.0})
    with pytest.raises(ConfigError, match="multiplier_lr"):
        PPOLagConfig(multiplier_lr=float("nan"))
    with pytest.raises(ConfigError, match="d_delay"):
        learner_config("ppo-pid", {"d_delay": 0})
    with pytest.raises(ConfigError, match="p_ema"):
        PIDLagConfig(p_ema=1.0)
    with pytest.raises(ConfigError, match="cost limit"):
        PayoffTable([{"protagonist": "p", "adversary": "a", "seed": 0, "true_return": 1}]).safety(
            -1
        )


def test_pcrpo_projection_removes_the_conflict_and_keeps_agreeing_gradients() -> None:
    g_r, g_c = torch.tensor([1.0, 0.0]), torch.tensor([-1.0, 1.0])
    p_r, p_c = project(g_r, g_c)
    assert float(p_r @ g_c) == pytest.approx(0.0, abs=1e-6)
    assert float(p_c @ g_r) == pytest.approx(0.0, abs=1e-6)
    same = torch.tensor([1.0, 1.0])
    assert all(torch.equal(a, b) for a, b in zip(project(g_r, same), (g_r, same), strict=True))


def test_switching_rules_follow_the_episode_cost() -> None:
    crpo, pcrpo = CRPOConfig(cost_limit=10.0, slack=1.0), PCRPOConfig(cost_limit=10.0, slack=1.0)
    assert crpo.direction(11.5, {}).cost_weight == 1.0
    assert crpo.direction(10.5, {}).reward_weight == 1.0
    assert pcrpo.direction(11.5, {}).reward_weight == 0.0
    assert pcrpo.direction(8.5, {}).cost_weight == 0.0
    band = pcrpo.direction(10.0, {})
    assert band.project and (band.reward_weight, band.cost_weight) == (0.4, 0.6)


def test_the_pid_multiplier_follows_its_controller() -> None:
    """P on the error's EMA, I clamped at 0, D on the cost EMA's rise; λ within [0, max]."""
    cfg = PIDLagConfig(cost_limit=10.0, kp=1.0, ki=0.1, kd=0.0, p_ema=0.0, multiplier_init=0.5)
    state = cfg.initial_state()
    way = cfg.direction(30.0, state)  # δ = 20: P 20, I 0.5 + 2
    assert state["multiplier"] == pytest.approx(22.5)
    assert way.cost_weight == pytest.approx(22.5 / 23.5)
    cfg.direction(0.0, state)  # δ = -10: P -10 pulls λ to 0 at once, I 2.5 - 1 = 1.5
    assert state["multiplier"] == 0.0 and state["integral"] == pytest.approx(1.5)
    capped = PIDLagConfig(cost_limit=0.0, multiplier_max=3.0)
    s2 = capped.initial_state()
    assert capped.direction(1e6, s2).cost_weight == pytest.approx(3.0 / 4.0)
    rising = PIDLagConfig(cost_limit=100.0, kp=0.0, ki=0.0, kd=1.0, d_ema=0.0, d_delay=2)
    s3 = rising.initial_state()
    rising.direction(10.0, s3)  # the cost rose by 10 over the delay: D alone gives λ
    assert s3["multiplier"] == pytest.approx(0.001 + 10.0)
    for _ in range(5):
        rising.direction(10.0, s3)
    assert len(s3["history"]) == 2 and s3["multiplier"] == pytest.approx(0.001)


# -- learning -------------------------------------------------------------------------------
LIMIT = 20.0
FAST = {"n_steps": 500, "batch_size": 100, "learning_rate": 2e-3, "lr_decay": False}
FAST |= {"log_std_init": -0.5, "cost_limit": LIMIT}
TUNED = {
    "ppo-lag": {"multiplier_lr": 0.5},
    "ppo-pid": {"ki": 0.05},
    "crpo": {"slack": 0.5},
    "pcrpo": {"slack": 0.5},
}


def _evaluate(policy: Any, seed: int = 7, episodes: int = 10) -> tuple[float, float]:
    game = advgame.make(REACHER, disruptors=[])
    results = advgame.rollout(game, {"protagonist": policy}, seed=seed, episodes=episodes)
    game.close()
    return float(np.mean([r.true_return for r in results])), float(
        np.mean([r.cost for r in results])
    )


@pytest.mark.parametrize("algo", sorted(SAFE_LEARNERS))
def test_each_learner_brings_the_cost_under_its_limit(algo: str) -> None:
    space = advgame.make(REACHER, disruptors=[]).action_space("protagonist")
    space.seed(0)
    floor, random_cost = _evaluate(lambda obs: space.sample())
    assert random_cost > 2 * LIMIT  # the untrained behaviour violates the constraint
    cfg = SAFE_LEARNERS[algo](**FAST, **TUNED[algo])
    learner = cfg.make_learner([team_factory(REACHER, preset="default")], 0, 10_000)
    learner.learn(10_000)
    ret, cost = _evaluate(lambda obs: learner.predict({"protagonist": obs})["protagonist"])
    assert cost <= LIMIT, (algo, cost)
    assert ret > floor, (algo, ret, floor)


def test_a_seeded_learner_reproduces_exactly() -> None:
    def trained() -> dict[str, torch.Tensor]:
        learner = PPOLagConfig(n_steps=100, batch_size=50).make_learner(
            [team_factory(REACHER, preset="cost-gauss-0.3")], 3, 200
        )
        learner.learn(200)
        return learner.model.state_dict()

    a, b = trained(), trained()
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


def _state(run: Path) -> dict[str, Any]:
    return json.loads((run / "state.json").read_text())


def test_a_constrained_run_killed_by_sigkill_resumes_to_the_end(tmp_path: Path) -> None:
    run, iterations = tmp_path / "run", 5
    script = Path(sys.executable).with_name("advgame")
    command = [str(script), "train", "--method", "ppo-lag", "--scenario", REACHER]
    command += ["--preset", "cost-gauss-0.3", "--iterations", str(iterations)]
    command += ["--protagonist-steps", "200", "--eval-episodes", "1", "--no-progress"]
    command += ["--run-dir", str(run), "--set", 'protagonist_hparams={"n_steps": 200}']
    proc = subprocess.Popen(
        command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env={**os.environ, "OMP_NUM_THREADS": "1"},
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            assert proc.poll() is None, proc.communicate()[1]
            if (run / "state.json").exists() and _state(run)["iteration"] >= 1:
                break
            time.sleep(0.05)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.communicate()
    done = _state(run)["iteration"]
    assert 1 <= done < iterations, "the kill came too late to test resume"
    saved = torch.load(run / _state(run)["checkpoint"] / "ppo-lag_constraint.pt")
    assert float(saved["multiplier"]) >= 0.0

    assert advgame.cli.main(["resume", str(run), "--no-progress"]) == 0
    assert _state(run)["iteration"] == iterations
    final = run / _state(run)["checkpoint"]
    assert {"ppo-lag_actors.pt", "ppo-lag_learner.pt", "ppo-lag_constraint.pt"} <= {
        p.name for p in final.iterdir()
    }
    rows = (run / "progress.csv").read_text().splitlines()
    assert len(rows) == iterations + 1 and "protagonist_phase_true_cost" in rows[0]


def test_learned_adversaries_train_against_a_constrained_protagonist(tmp_path: Path) -> None:
    from advgame.training import TrainConfig, train
    from advgame.training.population import Population

    cfg = TrainConfig(
        scenario=REACHER,
        preset="default",
        learned=None,  # observation, action and cost adversaries, all learned
        protagonist_algo="crpo",
        protagonist_hparams={"n_steps": 100, "cost_limit": 10.0},
        adversary_hparams={"n_steps": 128},
        iterations=1,
        protagonist_steps=100,
        adversary_steps=128,
        eval_episodes=1,
    )
    run = train(cfg, tmp_path / "run", progress=False)
    pop = Population.load(run / "population.json")
    learned = {m.agent for m in pop if m.learned}
    assert learned == {"observation_adversary", "action_adversary", "cost_adversary"}
    row = (run / "progress.csv").read_text().splitlines()
    header, values = row[0].split(","), row[1].split(",")
    cost = float(values[header.index("eval_attacked_cost")])
    assert 0.0 <= cost <= 50.0  # a 50-step episode costs at most 1 per step


def test_the_report_gains_episode_cost_and_constraint_satisfaction(tmp_path: Path) -> None:
    from advgame.evaluation import AdversarySetup, evaluate, population_jobs
    from advgame.reports.report import write_report

    def spin(obs: Any) -> list[float]:  # full torque: the fingertip exceeds the speed limit
        return [1.0, 1.0]

    setups = {
        "nominal": AdversarySetup.nominal(),
        "cost-0.3": AdversarySetup.from_preset(REACHER, "cost-gauss-0.3"),
    }
    jobs = population_jobs(
        REACHER, {"spin": spin, "still": lambda obs: [0.0, 0.0]}, setups, seeds=(0, 1)
    )
    table = evaluate(jobs, workers=1, progress=False)
    rows = {(r["protagonist"], r["adversary"]): r for r in table.safety(limit=10.0)}
    costs = table.values("spin", "nominal", "cost")
    assert rows["spin", "nominal"]["cost"] == pytest.approx(costs.mean())
    assert rows["spin", "nominal"]["satisfied"] == pytest.approx(np.mean(costs <= 10.0))
    assert rows["spin", "nominal"]["satisfied"] < 1.0 and rows["still", "nominal"]["cost"] == 0.0
    assert rows["still", "cost-0.3"]["satisfied"] == 1.0  # observed-cost noise is not true cost
    report = write_report(tmp_path, "safe", table, cost_limit=10.0).read_text()
    assert "## Safety" in report and "satisfied" in report
    assert (tmp_path / "safety.png").stat().st_size > 0


@pytest.mark.parametrize("algo", ["ppo-lag", "ppo-pid"])
def test_save_and_load_restore_the_multiplier_and_the_learner(tmp_path: Path, algo: str) -> None:
    cfg = learner_config(algo, {"n_steps": 100, "batch_size": 50, "cost_limit": 1.0})
    fns = [team_factory(REACHER, preset="default")]
    learner = cfg.make_learner(fns, 0, 400)
    learner.learn(200)
    assert learner.multiplier is not None and learner.multiplier > cfg.multiplier_init
    learner.save(tmp_path)
    back = cfg.load_learner(tmp_path, fns)
    assert back.multiplier == learner.multiplier and back.episode_cost == learner.episode_cost
    assert back.algo_state.keys() == learner.algo_state.keys()
    assert back.steps == learner.steps == 200
    a, b = learner.model.state_dict(), back.model.state_dict()
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)
    back.learn(100)  # and it trains on
    assert back.steps == 300


def test_the_report_limit_comes_from_the_runs_learner_configs(tmp_path: Path) -> None:
    from advgame.reports.report import DEFAULT_COST_LIMIT, runs_cost_limit

    for name, cfg in {
        "tight": {"protagonist_algo": "crpo", "protagonist_hparams": {"cost_limit": 4.0}},
        "omnisafe": {"protagonist_algo": "ppo-lag", "protagonist_hparams": None},
        "plain": {"protagonist_algo": "ppo", "protagonist_hparams": None},
    }.items():
        (tmp_path / name).mkdir()
        (tmp_path / name / "config.json").write_text(json.dumps(cfg))
    assert runs_cost_limit([tmp_path / "tight", tmp_path / "omnisafe"]) == 4.0
    assert runs_cost_limit([tmp_path / "omnisafe"]) == DEFAULT_COST_LIMIT
    assert runs_cost_limit([tmp_path / "plain"]) is None


def test_advgame_evaluate_reports_cost_under_the_papers_safe_settings(tmp_path: Path) -> None:
    from advgame.training import TrainConfig, train

    runs = []
    for algo in ("crpo", "pcrpo"):
        cfg = TrainConfig(
            scenario=REACHER,
            preset="default",
            learned=[],
            protagonist_algo=algo,  # type: ignore[arg-type]
            protagonist_hparams={"n_steps": 64, "cost_limit": 7.0},
            iterations=1,
            protagonist_steps=64,
            adversary_steps=0,
            eval_episodes=0,
        )
        runs.append(str(train(cfg, tmp_path / algo, progress=False)))
    out = tmp_path / "results"
    argv = ["evaluate", *runs, "--out", str(out), "--seeds", "1", "--workers", "1"]
    assert advgame.cli.main(argv) == 0
    table = PayoffTable.from_csv(out / "payoff.csv")
    assert {"random action-gauss-0.3", "random cost-gauss-0.3"} <= set(table.adversaries)
    report = (out / "report.md").read_text()
    assert "## Safety" in report and "cost ≤ 7)" in report
    for row in table.safety(7.0):
        assert 0.0 <= row["satisfied"] <= 1.0 and 0.0 <= row["cost"] <= 50.0


def test_target_kl_stops_the_epochs_early_and_none_runs_them_all() -> None:
    def epochs(**options: Any) -> float:
        cfg = PPOLagConfig(n_steps=128, batch_size=64, n_epochs=8, **options)
        learner = cfg.make_learner([team_factory(REACHER, preset="default")], 0, 256)
        learner.learn(256)
        return learner.diagnostics["epochs"]

    assert epochs() == 8
    assert epochs(target_kl=1e-12) == 1  # the first epoch always runs, then the KL is checked
    assert 1 <= epochs(target_kl=0.02) <= 8
    with pytest.raises(ConfigError, match="target_kl"):
        PPOLagConfig(target_kl=0.0)
    with pytest.raises(ConfigError, match="target_kl"):
        learner_config("ippo", {"target_kl": "small"})
