"""`advgame.evaluation` and `advgame.reports.report`: metric math, jobs, real payoff tables, reports."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

import advgame
from advgame.adversaries import ConstantAdversary, GaussianAdversary, UniformAdversary
from advgame.core.episodes import rollout
from advgame.errors import ConfigError, UnknownNameError, UnknownScenarioError
from advgame.evaluation import (
    SEED_STRIDE,
    AdversarySetup,
    EvalJob,
    PayoffTable,
    budget_sweep,
    ci95,
    cvar,
    degradation,
    evaluate,
    population_jobs,
    run_job,
    shift_grid,
    worst_case,
)
from advgame.reports.report import (
    plot_budget_curve,
    plot_heatmap,
    plot_training_curves,
    write_report,
)

ROOT = Path(__file__).resolve().parents[1]
PNG = b"\x89PNG\r\n\x1a\n"


def hopper_controller(obs: np.ndarray) -> np.ndarray:
    """A frozen Hopper protagonist: a plain module-level callable, so worker processes load it."""
    return np.tanh(np.asarray(obs[2:5], dtype=np.float64) - 0.1).astype(np.float32)


def population() -> dict[str, AdversarySetup]:
    return {
        "nominal": AdversarySetup.nominal(),
        "gauss": AdversarySetup(
            {"preset": "state-gauss-0.1"}, {"observation_adversary": GaussianAdversary(std=0.1)}
        ),
        "uniform": AdversarySetup.from_preset("Hopper-v5", "state-uniform-0.2-0.8"),
    }


def assert_png(path: Path) -> None:
    data = Path(path).read_bytes()
    assert data[:8] == PNG and len(data) > 2000, path


# -- metric math, by hand ---------------------------------------------------------------------
def test_cvar_is_the_mean_of_the_ceil_alpha_n_lowest() -> None:
    assert cvar([5.0, 1.0, 3.0, 2.0], alpha=0.5) == 1.5  # k = 2: (1 + 2) / 2
    assert cvar([5.0, 1.0, 3.0, 2.0], alpha=0.3) == 1.5  # k = ceil(1.2) = 2
    assert cvar([5.0, 1.0, 3.0, 2.0], alpha=0.25) == 1.0  # k = 1: the minimum
    assert cvar(range(10), alpha=0.3) == 1.0  # 0.3 * 10 = 3.0000000000000004 still takes 3
    assert cvar(range(10), alpha=0.25) == 1.0  # k = ceil(2.5) = 3: (0 + 1 + 2) / 3
    assert cvar([4.0, -2.0], alpha=1.0) == 1.0  # alpha = 1: the mean
    assert cvar([7.0], alpha=0.01) == 7.0
    for alpha in (0.0, -0.1, 1.5):
        with pytest.raises(ConfigError, match="alpha"):
            cvar([1.0], alpha)
    with pytest.raises(ConfigError, match="no values"):
        cvar([], 0.1)


def test_worst_case_degradation_and_interval() -> None:
    assert worst_case({"gauss": 3.0, "push": -1.0, "wind": 2.0}) == -1.0
    assert worst_case([4.0, 2.5]) == 2.5
    with pytest.raises(ConfigError):
        worst_case({})
    assert degradation(10.0, 6.0) == pytest.approx(0.4)
    assert degradation(10.0, 12.0) == pytest.approx(-0.2)  # the adversary helped
    assert degradation(-10.0, -15.0) == pytest.approx(0.5)  # |nominal| keeps the sign meaningful
    assert math.isnan(degradation(0.0, 1.0)) and math.isnan(degradation(math.nan, 1.0))
    # t(0.975, df=1) = 12.706; std([1, 3], ddof=1) / sqrt(2) = 1
    assert ci95([1.0, 3.0]) == pytest.approx(12.706)
    # df=3: t = 3.182; std([1, 2, 3, 4], ddof=1) = 1.2910; / 2
    assert ci95([1.0, 2.0, 3.0, 4.0]) == pytest.approx(3.182 * 1.2909944 / 2)
    assert math.isnan(ci95([5.0]))


def literal_table() -> PayoffTable:
    rows = []
    for adv, seed, ret in [("nominal", 0, 10.0), ("nominal", 1, 12.0), ("A", 0, 8.0),
                           ("A", 1, 6.0), ("B", 0, 9.0), ("B", 1, 3.0)]:  # fmt: skip
        rows.append({"protagonist": "p", "adversary": adv, "seed": seed, "true_return": ret})
    rows += [{"protagonist": "q", "adversary": "A", "seed": s, "true_return": r}
             for s, r in [(0, 1.0), (1, 2.0)]]  # fmt: skip
    return PayoffTable(rows)


def test_payoff_table_metrics_match_hand_computation() -> None:
    table = literal_table()
    p, q = table.metrics(alpha=0.25)
    # p: nominal (10 + 12) / 2 = 11; others [8, 6, 9, 3]: mean 6.5; cells A = 7, B = 6
    assert p["nominal"] == 11.0 and p["mean"] == 6.5
    assert p["worst"] == 6.0 and p["worst_adversary"] == "B"
    assert p["cvar"] == 3.0  # ceil(0.25 * 4) = 1 lowest
    assert p["degradation"] == pytest.approx(4.5 / 11)
    assert p["worst_degradation"] == pytest.approx(5 / 11)
    assert p["nominal_ci95"] == pytest.approx(12.706)  # seeds 10, 12: std/sqrt(2) = 1
    assert p["worst_ci95"] == pytest.approx(12.706 * 3)  # B's seeds 9, 3: std/sqrt(2) = 3
    assert (p["adversaries"], p["episodes"]) == (2, 4)
    assert table.metrics(alpha=0.5)[0]["cvar"] == 4.5  # (3 + 6) / 2
    # q never met the nominal game: no nominal, so no degradation
    assert math.isnan(q["nominal"]) and math.isnan(q["degradation"])
    assert q["worst"] == 1.5 and q["worst_adversary"] == "A"
    ps, adv, m = table.matrix()
    assert ps == ["p", "q"] and adv == ["nominal", "A", "B"]
    np.testing.assert_array_equal(m, [[11.0, 7.0, 6.0], [np.nan, 1.5, np.nan]])
    np.testing.assert_array_equal(table.matrix("min")[2][0], [10.0, 6.0, 3.0])
    with pytest.raises(ConfigError, match="Did you mean"):
        table.matrix("meen")


def test_cell_interval_is_over_seed_means_not_episodes() -> None:
    rows = [{"protagonist": "p", "adversary": "A", "seed": s, "true_return": r}
            for s, r in [(0, 1.0), (0, 3.0), (1, 5.0)]]  # fmt: skip
    (cell,) = PayoffTable(rows).cells()
    assert cell["episodes"] == 3 and cell["seeds"] == 2
    assert cell["mean"] == 3.0  # over episodes: (1 + 3 + 5) / 3
    assert cell["std"] == pytest.approx(np.std([2.0, 5.0], ddof=1))  # seed means 2 and 5
    assert cell["ci95"] == pytest.approx(12.706 * 1.5)
    with pytest.raises(ConfigError, match="lacks"):
        PayoffTable([{"protagonist": "p", "adversary": "A"}])


# -- jobs -------------------------------------------------------------------------------------
def job(**kw: object) -> EvalJob:
    base: dict = {"scenario": "Hopper-v5", "protagonist": "hop",
                  "protagonist_spec": hopper_controller}  # fmt: skip
    return EvalJob(**{**base, **kw})


@pytest.mark.parametrize(("kw", "err", "match"), [
    ({"scenario": "Hoper-v5"}, UnknownScenarioError, 'Did you mean "Hopper-v5"'),
    ({"episodes": 0}, ConfigError, "episodes must be an int >= 1"),
    ({"episodes": SEED_STRIDE + 1}, ConfigError, "use more seeds"),
    ({"seeds": (0, 0)}, ConfigError, "distinct"),
    ({"seeds": (-1,)}, ConfigError, ">= 0"),
    ({"seeds": ("a",)}, ConfigError, "seeds must be ints"),
    ({"make_kwargs": {"preset": "default", "disruptors": {}}}, ConfigError, "both preset"),
    ({"make_kwargs": {"phase": "test"}}, ConfigError, "'train' or 'eval'"),
    ({"protagonist_spec": 3}, ConfigError, "PolicySpec"),
    ({"adversary_specs": {"observation_adversary": "gauss"}}, ConfigError, "observation_adversary"),
    ({"protagonist": ""}, ConfigError, "protagonist must be a non-empty"),
    ({"tags": {"seed": 3}}, ConfigError, "tags"),
])  # fmt: skip
def test_eval_job_rejects_bad_values(kw: dict, err: type, match: str) -> None:
    with pytest.raises(err, match=match):
        job(**kw)


def test_eval_job_defaults_and_errors_at_run_time() -> None:
    j = job(seeds=3, make_kwargs={"preset": "default"})
    assert j.seeds == (3,) and j.make_kwargs == {"phase": "eval", "preset": "default"}
    bad = job(make_kwargs={"preset": "default"}, adversary="typo",
              adversary_specs={"observation_adversry": GaussianAdversary()})  # fmt: skip
    with pytest.raises(ConfigError, match=r"'hop' vs 'typo'.*observation_adversry"):
        run_job(bad)
    with pytest.raises(UnknownNameError, match=r"state-gauss-0\.1"):
        AdversarySetup.from_preset("Hopper-v5", "state-gaus-0.1")
    with pytest.raises(ConfigError, match="AdversarySetup"):
        population_jobs("Hopper-v5", {"hop": hopper_controller}, {"x": {"preset": "default"}})
    with pytest.raises(ConfigError, match="workers"):
        evaluate([job()], workers=0)
    lam = job(protagonist_spec=lambda obs: np.zeros(3, np.float32))
    with pytest.raises(ConfigError, match="module-level functions"):
        evaluate([lam, lam], workers=2, progress=False)  # fails before any process starts


def test_consecutive_seeds_with_several_episodes_never_replay_an_episode() -> None:
    rows = run_job(job(seeds=(0, 1), episodes=2, make_kwargs={"disruptors": {}}))
    assert [(r["seed"], r["episode"]) for r in rows] == [(0, 0), (0, 1), (1, 0), (1, 1)]
    # with reset seeds s + i, episode 1 of seed 0 would replay episode 0 of seed 1
    assert len({r["true_return"] for r in rows}) == 4


# -- real runs --------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def hopper_table() -> PayoffTable:
    jobs = population_jobs("Hopper-v5", {"hop": hopper_controller}, population(), seeds=(0, 1))
    return evaluate(jobs, workers=1, progress=False)


def test_population_on_hopper(hopper_table: PayoffTable) -> None:
    rows = hopper_table.rows
    assert [(r["adversary"], r["seed"], r["episode"]) for r in rows] == [
        (a, s, 0) for a in ("nominal", "gauss", "uniform") for s in (0, 1)
    ]
    assert isinstance(population()["uniform"].specs["observation_adversary"], UniformAdversary)
    assert all(r["length"] > 0 and r["true_return"] == r["observed_return"] for r in rows)
    by = {(r["adversary"], r["seed"]): r for r in rows}
    # the nominal cell is the plain rollout of the undisrupted game, seed for seed
    game = advgame.make("Hopper-v5", disruptors={}, phase="eval")
    for seed in (0, 1):
        (res,) = rollout(game, {"protagonist": hopper_controller}, seed=seed * SEED_STRIDE)
        assert by[("nominal", seed)]["true_return"] == res.true_return
        assert by[("nominal", seed)]["clipped"] == 0
        # the adversaries really played: the controller saw other observations
        assert by[("gauss", seed)]["true_return"] != res.true_return
        assert by[("uniform", seed)]["true_return"] != res.true_return
    (m,) = hopper_table.metrics(alpha=0.5)
    cell_means = {
        a: np.mean([by[(a, s)]["true_return"] for s in (0, 1)]) for a in ("gauss", "uniform")
    }
    assert m["worst"] == min(cell_means.values()) <= m["mean"]
    assert m["cvar"] <= m["mean"] and m["episodes"] == 4


def test_pool_gives_identical_rows(
    hopper_table: PayoffTable, monkeypatch: pytest.MonkeyPatch
) -> None:
    # workers import this test module by name (tests.test_evaluation): put its root on the path
    monkeypatch.syspath_prepend(str(ROOT))
    jobs = population_jobs("Hopper-v5", {"hop": hopper_controller}, population(), seeds=(0, 1))
    pooled = evaluate(jobs, workers=2, progress=False)
    assert pooled.rows == hopper_table.rows
    # a seed's rows do not depend on which other seeds share its job
    (alone,) = run_job(
        job(
            adversary="gauss",
            seeds=(1,),
            **{
                "make_kwargs": {"preset": "state-gauss-0.1"},
                "adversary_specs": {"observation_adversary": GaussianAdversary(std=0.1)},
            },
        )
    )
    assert alone == pooled.rows[3]


def test_pool_explains_a_job_workers_cannot_import(monkeypatch: pytest.MonkeyPatch) -> None:
    keep = [p for p in sys.path if p not in ("", ".", str(ROOT))]
    monkeypatch.setattr(sys, "path", keep)  # this test module is not importable by workers
    with pytest.raises(ConfigError, match=r"cannot load a job.*No module named 'tests"):
        evaluate([job(), job(seeds=(1,))], workers=2, progress=False)


def test_csv_and_json_round_trip(hopper_table: PayoffTable, tmp_path: Path) -> None:
    tagged = {**hopper_table.rows[0], "budget": 0.05, "note": "x"}
    table = PayoffTable([*hopper_table.rows, tagged])
    assert table.columns()[-2:] == ["budget", "note"]
    for back in (PayoffTable.from_csv(table.to_csv(tmp_path / "t.csv")),
                 PayoffTable.from_json(table.to_json(tmp_path / "t.json"))):  # fmt: skip
        assert back.rows == table.rows  # floats, ints, bools and missing tags all survive
        assert [type(v) for v in back.rows[0].values()] == [type(v) for v in table.rows[0].values()]


def test_shift_grid_includes_interval_ends_and_reaches_the_model() -> None:
    grid = shift_grid("Ant-v5", "shift-uniform", points=3)
    entries = list(grid)
    assert len(entries) == 9 and len({n for n, _ in entries}) == 9
    values = [spec["dynamics_adversary"].value for _, spec in entries]
    assert {g for g, _ in values} == {9.81, (9.81 + 19.82) / 2, 19.82}
    assert {w for _, w in values} == {0.8, 1.0, 1.2}
    name, spec = entries[-1]
    assert name == "gravity=19.82,wind=1.2" and isinstance(
        spec["dynamics_adversary"], ConstantAdversary
    )
    game = advgame.make("Ant-v5", preset="shift-uniform", phase="eval", max_episode_steps=3)
    rollout(game, {"protagonist": lambda o: np.zeros(8, np.float32), **spec}, seed=0)
    assert game.task.sim.model.opt.gravity[2] == pytest.approx(-19.82)
    with pytest.raises(ConfigError, match="no dynamics disruptor"):
        shift_grid("Ant-v5", "default")
    with pytest.raises(ConfigError, match="points"):
        shift_grid("Ant-v5", "shift-uniform", points=1)


# -- budget sweep and reports -----------------------------------------------------------------
def test_budget_sweep_and_report(hopper_table: PayoffTable, tmp_path: Path) -> None:
    sigmas = [0.0, 0.05, 0.1, 0.15]
    jobs = budget_sweep("Hopper-v5", {"hop": hopper_controller}, sigmas, seeds=(0, 1))
    assert [j.adversary for j in jobs] == ["observation-0", "observation-0.05",
                                           "observation-0.1", "observation-0.15"]  # fmt: skip
    sweep = evaluate(jobs, progress=False)
    assert sorted({r["budget"] for r in sweep.rows}) == sigmas
    # σ = 0 noise is the nominal game exactly
    zero = [r["true_return"] for r in sweep.rows if r["budget"] == 0.0]
    nominal = [r["true_return"] for r in hopper_table.rows if r["adversary"] == "nominal"]
    assert zero == nominal
    curve = plot_budget_curve(sweep, tmp_path / "budget.png")
    heat = plot_heatmap(hopper_table, tmp_path / "heat.png")
    with pytest.raises(ConfigError, match="budget_sweep"):
        plot_budget_curve(hopper_table, tmp_path / "none.png")
    runs = {}
    for name, shift in (("run-a", 0.0), ("run-b", 5.0)):
        runs[name] = tmp_path / name / "progress.csv"
        runs[name].parent.mkdir()
        lines = ["iteration,protagonist_return,adversary_return,fps"]
        lines += [f"{i},{10 * i + shift},{-10 * i - shift},100" for i in range(5)]
        runs[name].write_text("\n".join(lines) + "\n")
    train = plot_training_curves({**runs, "missing": tmp_path / "nope.csv"}, tmp_path / "train.png")
    assert train is not None
    assert plot_training_curves({"missing": tmp_path / "nope.csv"}, tmp_path / "x.png") is None
    assert not (tmp_path / "x.png").exists()
    md = write_report(tmp_path / "report", "Hopper robustness", hopper_table,
                      extra_sections={"Notes": "hand-written controller"},
                      figures={"return vs budget": curve, "training": train})  # fmt: skip
    for png in (curve, heat, train, md.parent / "heatmap.png"):
        assert_png(png)
    text = md.read_text()
    (m,) = hopper_table.metrics()
    assert md.name == "report.md" and text.startswith("# Hopper robustness")
    for needle in ("## Robust metrics", "## Payoff matrix", "| hop |", "gauss", "uniform",
                   "](heatmap.png)", "](../budget.png)", "## Notes", "How this was measured",
                   f"{m['worst']:.4g}", f"{m['nominal']:.4g}"):  # fmt: skip
        assert needle in text, needle
    assert PayoffTable.from_csv(md.parent / "payoff.csv").rows == hopper_table.rows
