"""Campaigns: a tiny grid trained in pieces, resumed without redoing finished runs, tabled."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

import advgame
from advgame.cli import main
from advgame.errors import ConfigError, FileFormatError
from advgame.evaluation import PayoffTable
from advgame.workflows.campaign import load_campaign, run_dir, table_status

TINY = """
scenario = "Hopper-v5"
methods = ["ppo", "atla"]
seeds = [0, 1]

[train]
iterations = 1
protagonist_steps = 128
adversary_steps = 128
eval_episodes = 0
protagonist_hparams = { n_steps = 64 }
adversary_hparams = { n_steps = 64 }

[evaluate]
adversaries = ["attack:random", "attack:mad"]
seeds = 2
"""


def _stamps(out: Path, runs: list[str]) -> dict[str, int]:
    return {r: (run_dir(out, r) / "state.json").stat().st_mtime_ns for r in runs}


@pytest.fixture(scope="module")
def grid(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The tiny campaign file, in a folder of its own (its output goes beside it)."""
    spec = tmp_path_factory.mktemp("campaign") / "tiny.toml"
    spec.write_text(TINY)
    return spec


def test_a_grid_trains_in_pieces_resumes_and_writes_the_table(
    grid: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    spec, tmp_path = grid, grid.parent
    out = tmp_path / "tiny"
    first = ["campaign", str(spec), "--workers", "1", "--no-progress"]
    assert main([*first, "--stage", "train", "--runs", "ppo-s7"]) == 2
    assert "No run 'ppo-s7' in the campaign; its runs: ppo-s0" in capsys.readouterr().err
    # a chosen piece, with progress: stderr is a file here, so a line per iteration and run
    assert (
        main(["campaign", str(spec), "--workers", "1", "--stage", "train", "--runs", "ppo-s1"]) == 0
    )
    err = capsys.readouterr().err
    assert "train Hopper-v5 ppo-s1: 128/128 steps (100 %)" in err and "iteration 1/1 in" in err
    assert "campaign tiny: 1/1 runs (100 %)" in err and "finished: ppo-s1" in err
    status = json.loads((out / "status.json").read_text())
    assert [r for r, s in status["runs"].items() if s["state"] == "done"] == ["ppo-s1"]
    assert main([*first, "--stage", "train", "--max-runs", "1"]) == 0  # the next unfinished one
    status = json.loads((out / "status.json").read_text())
    states = {r: s["state"] for r, s in status["runs"].items()}
    assert states == {
        "ppo-s0": "done",
        "ppo-s1": "done",
        "atla-s0": "pending",
        "atla-s1": "pending",
    }
    campaign = load_campaign(spec)
    assert table_status(campaign, out, ["ppo-s0", "ppo-s1"]) == {"played": 0, "cells": 6}
    before = _stamps(out, ["ppo-s0", "ppo-s1"])
    for run in (
        "ppo-s0",
        "ppo-s1",
    ):  # finished runs are compact, in finished/, nothing left in runs/
        assert run_dir(out, run) == out / "finished" / run and not (out / "runs" / run).exists()
        assert [f.name for f in (out / "finished" / run / "checkpoints").iterdir()] == ["iter_0001"]
        assert not (out / "finished" / run / "tb").exists()
        with (out / "finished" / run / "learning.csv").open() as f:  # the logs' scalars stay
            logged = {(r["writer"], r["tag"]) for r in csv.DictReader(f)}
        assert ("loop", "loop/protagonist_phase_true_return") in logged
        assert any(w.startswith("protagonist") and t.startswith("train/") for w, t in logged)
    assert main(["campaign", str(spec), "--workers", "2", "--no-progress"]) == 0
    assert _stamps(out, ["ppo-s0", "ppo-s1"]) == before  # finished runs are not trained again
    status = json.loads((out / "status.json").read_text())
    assert all(s["state"] == "done" for s in status["runs"].values())
    assert status["evaluated"] == ["atla-s0", "atla-s1", "ppo-s0", "ppo-s1"]
    table = (out / "campaign.md").read_text()
    assert "| ppo | 2 |" in table and "| atla | 2 |" in table
    assert "| worst adversary | worst |" in table  # the column names any kind of adversary
    lines = (out / "campaign.csv").read_text().splitlines()
    assert lines[0].startswith("method,seeds,median_agent,natural,worst")
    assert len(lines) == 3
    assert "![training curves](curves.png)" in table and (out / "curves.png").stat().st_size
    rows = PayoffTable.from_csv(out / "results" / "payoff.csv").rows
    cells = {(r["protagonist"], r["adversary"]) for r in rows}
    assert table_status(campaign, out, status["evaluated"]) == {"played": 12, "cells": 12}
    assert len(cells) == 12 and len(list((out / "results" / "parts").iterdir())) == 12
    # Once more, with one worker (so other units): nothing is trained or played again.
    parts = {p: p.stat().st_mtime_ns for p in (out / "results" / "parts").iterdir()}
    runs = _stamps(out, list(status["runs"]))
    assert main(["campaign", str(spec), "--workers", "1", "--no-progress"]) == 0
    assert {p: p.stat().st_mtime_ns for p in (out / "results" / "parts").iterdir()} == parts
    assert _stamps(out, list(status["runs"])) == runs


def test_bad_campaign_files_are_clear_errors(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    for text, words in [
        ('methods = ["nope"]\nscenario = "Hopper-v5"', "METHODS"),
        ('methods = ["ppo"]\nscenario = "Hopper-v5"\n[train]\nbogus = 1', "bogus"),
        ('methods = ["ppo"]\nscenario = "Hopper-v5"\nseeds = [-1]', "seeds"),
        ("methods = [", "not valid TOML"),
        ('methods = ["ppo"]\nscenario = "Hopper-v5"\nextra = 1', "unknown keys"),
        ('methods = ["noisy"]\nscenario = "Hopper-v5"\n[train.noisy]\nmethod = "nope"', "variants"),
        (
            'methods = ["ppo-s1"]\nscenario = "Hopper-v5"\n[train.ppo-s1]\nmethod = "ppo"',
            "-s<digits>",
        ),
        ('methods = ["ppo", "ppo"]\nscenario = "Hopper-v5"', "distinct"),
        ('methods = ["ppo"]\nscenario = "Hopper-v5"\nseeds = 3', "list of distinct ints"),
        ('methods = ["ppo"]\nscenario = "Hopper-v5"\n[train.ppo]\nseeds = [1, 1]', "train.ppo"),
        ('methods = ["ppo"]\nscenario = "Hopper-v5"\n[train.ppo]\nseeds = []', "train.ppo"),
        ('methods = ["ppo"]\nscenario = "Hopper-v5"\nzoo = "Hopper/x"', "zoo must be a folder"),
    ]:
        bad.write_text(text)
        with pytest.raises(ConfigError, match=words):
            load_campaign(bad)


def test_a_bad_evaluate_section_is_refused_before_anything_trains(tmp_path: Path) -> None:
    """Issue 36: the [evaluate] section is read as the evaluation reads it, when the file is."""
    head = 'scenario = "InvertedPendulum-v5"\nmethods = ["ppo"]\n[evaluate]\n'
    bad = tmp_path / "bad.toml"
    for text, words in [
        ('threat = "atla"', "has no preset 'atla'"),  # the user's typo of the issue
        ('adversaries = ["attack:madd"]', "Unknown attack 'madd'"),
        ('adversaries = ["atack:mad"]', "Unknown adversary column kind 'atack'"),
        ('adversaries = ["preset:nope"]', "nope"),
        ('adversaries = ["population:runs/x,lats=3"]', "Bad option"),
        ('adversaries = "attacks"', "must be a list of column specs"),
        ("threat = 3", "must be a preset name"),
        # a search or attack needs an observation budget in the threat model
        ('threat = "reward-gauss-0.1"\nexploitability = 100', "no bounded observation"),
    ]:
        bad.write_text(head + text)
        with pytest.raises(ConfigError, match=words):
            load_campaign(bad)
    good = head + 'adversaries = ["attacks", "population:runs/later,last=2"]\nthreat = "default"'
    bad.write_text(good)
    assert load_campaign(bad).threat == "default"  # runs named by columns may come later


def test_optimal_grid_overrides_reach_the_search_and_bad_ones_are_refused(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Issue 36: a campaign lengthens one candidate of the search (Walker2d's long recipe)."""
    from advgame.evaluation.attacks.optimal import OPTIMAL_GRID
    from advgame.workflows import campaign as campaign_module
    from advgame.workflows import suite

    head = 'scenario = "Hopper-v5"\nmethods = ["ppo"]\n[evaluate]\nexploitability = 100\n'
    path = tmp_path / "c.toml"
    path.write_text(head + "optimal_grid = { 4 = { steps_scale = 10 } }\n")
    campaign = load_campaign(path)
    grid = campaign.search_grid()
    assert grid is not None and grid[4] == {**OPTIMAL_GRID[4], "steps_scale": 10}
    assert grid[:4] == OPTIMAL_GRID[:4] and grid[5:] == OPTIMAL_GRID[5:]  # the rest read back
    assert OPTIMAL_GRID[4]["steps_scale"] == 5  # the default grid is not changed in place
    seen = {}
    monkeypatch.setattr(suite, "evaluate_runs", lambda runs, out, **kw: seen.update(kw))
    campaign_module._evaluate(campaign, tmp_path, [], 1, "local", None, False)
    assert seen["optimal_grid"] == grid and seen["exploitability_steps"] == 100
    search = campaign.search(workers=2)  # what --status counts: the same grid and steps
    assert search.grid == grid and search.steps == 100 and search.workers == 2
    path.write_text(head)
    assert load_campaign(path).search_grid() is None  # no override: OPTIMAL_GRID
    assert load_campaign(path).search().grid == OPTIMAL_GRID
    path.write_text(head.replace("100", "0"))
    assert load_campaign(path).search() is None  # no exploitability: no search
    for text, words in [
        ("optimal_grid = { 99 = { steps_scale = 2 } }", "OPTIMAL_GRID index"),
        ("optimal_grid = { x = { steps_scale = 2 } }", "OPTIMAL_GRID index"),
        ("optimal_grid = { 4 = 10 }", "a table of overrides"),
        ("optimal_grid = { 4 = { steps_scale = 0 } }", "steps_scale must be an int >= 1"),
        ('optimal_grid = { 4 = { algo = "sac" } }', "algo must be one of"),
    ]:
        path.write_text(head + text + "\n")
        with pytest.raises(ConfigError, match=words):
            load_campaign(path)


def test_status_counts_the_optimal_attacks_candidates_by_their_part_files(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--status`` says how much of the search is trained: its candidates, as the search keys
    them (one trained here through the runner, as the evaluate stage trains it)."""
    from advgame.evaluation.attacks.optimal import OPTIMAL_GRID, OptimalSearch, candidate_jobs
    from advgame.evaluation.table.protagonists import run_protagonist
    from advgame.runner.run import run_units
    from advgame.training.best_response import train_best_response
    from advgame.workflows.campaign import done_runs, search_status, write_status
    from advgame.workflows.suite import observation_agent

    spec = tmp_path / "c.toml"
    spec.write_text(
        'scenario = "Hopper-v5"\nmethods = ["ppo"]\nseeds = [0]\n[train]\niterations = 1\n'
        "protagonist_steps = 64\neval_episodes = 0\nprotagonist_hparams = { n_steps = 64 }\n"
        '[evaluate]\nthreat = "atla"\nexploitability = 64\n'
    )
    campaign, out = load_campaign(spec), tmp_path / "c"

    def counted() -> dict[str, int] | None:  # as --status counts: the finished runs' candidates
        out.mkdir(parents=True, exist_ok=True)
        return search_status(campaign, out, done_runs(write_status(campaign, out)))

    assert counted() == {
        "trained": 0, "candidates": 0, "trained_steps": 0, "steps": 0,
    }  # fmt: skip
    assert main(["campaign", str(spec), "--workers", "1", "--no-progress", "--stage", "train"]) == 0
    offered = [g for g in OPTIMAL_GRID if g.get("victims", "all") == "all"]
    steps = sum(64 * g.get("steps_scale", 1) for g in offered)
    assert counted() == {
        "trained": 0, "candidates": len(offered), "trained_steps": 0, "steps": steps,
    }  # fmt: skip
    search = OptimalSearch(steps=64, grid=OPTIMAL_GRID)
    protagonists = {"ppo-s0": run_protagonist(run_dir(out, "ppo-s0"))[1]}
    agent = observation_agent("Hopper-v5", "atla")
    (first, *_) = candidate_jobs("Hopper-v5", "atla", agent, protagonists, search)
    parts = out / "results" / "optimal" / "parts"
    run_units(train_best_response, [first[2]], parts_dir=parts)
    assert counted() == {
        "trained": 1, "candidates": len(offered), "trained_steps": first[2].steps, "steps": steps,
    }  # fmt: skip
    assert main(["campaign", str(spec), "--status"]) == 0
    words = f"optimal attack (finished runs): 1/{len(offered)} candidates trained"
    printed = capsys.readouterr().out
    assert words in printed
    assert "table (finished runs, without the optimal column): 0/" in printed


def test_a_method_may_have_more_seeds_than_the_others(tmp_path: Path) -> None:
    """Issue 36 item 4: more seeds where the intervals overlap, the other rows left alone."""
    path = tmp_path / "more.toml"
    path.write_text(
        'scenario = "Hopper-v5"\nmethods = ["ppo", "atla"]\nseeds = [0, 1, 2]\n'
        "[train.ppo]\nseeds = [0, 1, 2, 3, 4]\n"
    )
    campaign = load_campaign(path)
    assert campaign.method_runs("ppo") == [f"ppo-s{s}" for s in range(5)]
    assert campaign.method_runs("atla") == ["atla-s0", "atla-s1", "atla-s2"]
    assert campaign.config("ppo-s4").seed == 4  # "seeds" is the grid's, not a TrainConfig field


def test_a_variant_trains_as_its_method_with_its_own_fields(tmp_path: Path) -> None:
    path = tmp_path / "variants.toml"
    path.write_text(
        'scenario = "SafetyHopper-v5"\nmethods = ["crpo", "crpo-noisy"]\nseeds = [0, 1]\n'
        "[train]\niterations = 3\n"
        '[train.crpo-noisy]\nmethod = "crpo"\npreset = "action-gauss-0.3"\n'
    )
    campaign = load_campaign(path)
    assert campaign.method_runs("crpo") == ["crpo-s0", "crpo-s1"]
    assert campaign.method_runs("crpo-noisy") == ["crpo-noisy-s0", "crpo-noisy-s1"]
    plain, noisy = campaign.config("crpo-s1"), campaign.config("crpo-noisy-s1")
    assert noisy.protagonist_algo == plain.protagonist_algo == "crpo"
    assert (plain.preset, noisy.preset) == ("default", "action-gauss-0.3")
    assert noisy.iterations == 3 and noisy.seed == 1
    assert campaign.base_method("crpo-noisy") == "crpo"


def test_the_campaign_file_in_the_docs_loads(tmp_path: Path) -> None:
    text = (Path(__file__).parent.parent / "docs" / "zoo.md").read_text()
    block = text.split("```toml\n", 1)[1].split("```", 1)[0]
    (tmp_path / "doc.toml").write_text(block)
    campaign = load_campaign(tmp_path / "doc.toml")
    assert campaign.base_method("atla-wide") == "atla"
    assert campaign.config("atla-wide-s0").train_budget_scale == 2.0
    assert campaign.search_grid()[4]["steps_scale"] == 10


def test_the_zoo_campaign_files_load() -> None:
    for path in sorted((Path(__file__).parent.parent / "zoo").glob("*.toml")):
        campaign = load_campaign(path)
        assert campaign.runs()
        split = [r for m in campaign.methods for r in campaign.method_runs(m)]
        assert split == campaign.runs()  # each run in exactly its method's ("atla" ≠ "atla-sa")
        if "atla-lstm-sa" in campaign.methods:  # ATLA's kappa 0.3 weighs twice our KL
            from advgame.agents import SARecurrentPPOConfig

            hparams = campaign.config("atla-lstm-sa-s0").protagonist_hparams
            assert hparams["sa_kappa"] == SARecurrentPPOConfig().sa_kappa == 2 * 0.3, path


def test_the_median_agents_are_released_listed_and_played_from_the_zoo(
    grid: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Releasing the finished tiny campaign (the test above trained it; here it only tables)."""
    from advgame.workflows import zoo

    root = tmp_path / "zoo"
    args = ["campaign", str(grid), "--workers", "2", "--no-progress", "--release", str(root)]
    assert main(args) == 0
    found = {e.id: e for e in zoo.entries(root)}
    assert set(found) == {"hopper/ppo", "hopper/atla"}
    assert set(found["hopper/atla"].files) >= {"protagonist", "normalizer", "adversary"}
    assert "adversary" not in found["hopper/ppo"].files  # PPO trained against nobody
    # the file names no threat model: the entries record the one the attacks played in
    assert {e.threat for e in found.values()} == {"atla"}
    for e in found.values():
        zoo.verify(e, root)  # checksums match
    capsys.readouterr()
    assert main(["zoo", "list", "--root", str(root)]) == 0
    assert "hopper/atla" in capsys.readouterr().out
    monkeypatch.setenv("ADVGAME_ZOO", str(root))
    out = tmp_path / "res"
    assert main(["evaluate", "--zoo", "hopper/ppo", "--zoo", "hopper/atla", "--out", str(out),
                 "--seeds", "1", "--workers", "1", "--adversaries", "nominal", "--budgets"]) == 0  # fmt: skip
    assert "hopper/atla" in (out / "report.md").read_text()
    # each agent against its own released adversary: the demo's zoo table
    from advgame.evaluation.table.payoff import PayoffTable
    from advgame.workflows.demo import demo_zoo, zoo_summary

    report = demo_zoo(tmp_path / "demo-zoo", quick=True, workers=1, root=root)
    assert report is not None
    table = PayoffTable.from_csv(report.parent / "payoff.csv")
    assert table.protagonists == ["hopper/atla"]  # PPO has no adversary to play
    assert set(table.adversaries) == {"nominal", "attack mad", "attack optimal"}
    summary = zoo_summary(report.parent, root=root)
    line = next(row for row in summary.splitlines() if "hopper/atla" in row)
    # the demo's few attacks are named as what they are, not as the strongest: the worst cell
    # of the zoo's full table (every attack, as the manifest records it) is printed beside them
    assert "worst of these 2 attacks" in line and "strongest" not in summary
    atla = found["hopper/atla"]
    assert f"zoo's full table: worst {atla.worst_attack_return:5.0f} ({atla.worst_attack})" in line
    capsys.readouterr()
    both = ["evaluate", "--zoo", "hopper/ppo", "--zoo", "hopper/atla", "--zoo-adversaries"]
    assert main([*both, "--out", str(tmp_path / "x"), "--budgets"]) == 2
    assert "released without an adversary" in capsys.readouterr().err
    # a campaign on a changed task releases into a folder of its own, beside hopper/
    text = grid.read_text()
    grid.write_text('zoo = "hopper-shifted"\n' + text)
    try:
        assert main(args) == 0
    finally:
        grid.write_text(text)  # the module's other tests read the file as it was
    ids = {e.id for e in zoo.entries(root)}
    assert ids == {"hopper/ppo", "hopper/atla", "hopper-shifted/ppo", "hopper-shifted/atla"}
    (root / found["hopper/ppo"].files["protagonist"]["path"]).write_bytes(b"changed")
    with pytest.raises(FileFormatError, match="sha256"):
        zoo.load("hopper/ppo")


def test_every_released_agent_matches_its_manifest_and_plays() -> None:
    """The repository's zoo: checksums, and one short episode of each agent."""
    import advgame
    from advgame.core.episodes import rollout
    from advgame.workflows import zoo

    found = zoo.entries()
    if not found:
        pytest.skip(f"no agents released in {zoo.default_root()} yet")
    for e in found:
        spec = zoo.load(e.id)  # verifies the sha256 of every file
        game = advgame.make(e.scenario, preset=e.threat or "default", max_episode_steps=20)
        policies = spec if isinstance(spec, dict) else {"protagonist": spec}  # safe: actors
        [result] = rollout(game, policies, seed=0)
        assert result.length >= 1
        game.close()


SAFE = """
scenario = "SafetyHopper-v5"
methods = ["ppo", "ppo-lag"]
seeds = [0]

[train]
iterations = 1
protagonist_steps = 128
eval_episodes = 0
protagonist_hparams = { n_steps = 64 }

[evaluate]
adversaries = ["nominal"]
seeds = 2
cost_limit = 25
"""


def test_a_safe_campaign_tables_return_cost_and_satisfaction_per_method(tmp_path: Path) -> None:
    import csv

    spec = tmp_path / "safe.toml"
    spec.write_text(SAFE)
    assert main(["campaign", str(spec), "--workers", "1", "--no-progress"]) == 0
    out = tmp_path / "safe"
    rows = list(csv.DictReader((out / "results" / "payoff.csv").open()))
    table = (out / "campaign.md").read_text()
    assert "## Cost (limit 25 per episode)" in table
    assert "![training curves](curves.png)" in table and (out / "curves.png").stat().st_size
    for method in ("ppo", "ppo-lag"):
        costs = [float(r["cost"]) for r in rows if r["protagonist"] == f"{method}-s0"]
        share = 100 * sum(c <= 25 for c in costs) / len(costs)
        line = next(ln for ln in table.splitlines() if ln.startswith(f"| {method} | nominal |"))
        assert line.endswith(f"| {share:.0f} % |")
        assert f"| {sum(costs) / len(costs):.4g} |" in line
    # A constrained learner's agent is released as its actors file and plays from the zoo.
    from advgame.core.episodes import rollout
    from advgame.workflows import zoo

    root = tmp_path / "zoo"
    args = ["campaign", str(spec), "--workers", "1", "--no-progress", "--release", str(root)]
    assert main(args) == 0
    lag = zoo.entry("safetyhopper/ppo-lag", root)
    assert lag.algo == "ppo-lag" and set(lag.files) == {"protagonist"}
    assert lag.threat == ""  # a nominal column only: the table played no threat model
    policies = zoo.load("safetyhopper/ppo-lag", root)
    assert set(policies) == {"protagonist"}
    game = advgame.make("SafetyHopper-v5", max_episode_steps=5)
    assert rollout(game, policies, seed=0)[0].length >= 1
    spec.write_text(SAFE.replace("cost_limit = 25", "cost_limit = -1"))
    with pytest.raises(ConfigError, match="cost_limit"):
        load_campaign(spec)


def test_compact_keeps_the_last_checkpoint_without_its_replay_buffer(tmp_path: Path) -> None:
    from advgame.training.population import Population
    from advgame.workflows.campaign import compact

    run = tmp_path / "run"
    for it in (1, 2):
        folder = run / "checkpoints" / f"iter_{it:04d}"
        folder.mkdir(parents=True)
        (folder / "protagonist.zip").write_bytes(b"model")
        (folder / "protagonist_replay.pkl").write_bytes(b"buffer")  # an off-policy learner's
    from torch.utils.tensorboard import SummaryWriter

    writer = SummaryWriter(str(run / "tb" / "protagonist_0"))
    writer.add_scalar("train/critic_loss", 2.5, 100)
    writer.close()
    (run / "state.json").write_text(
        json.dumps({"iteration": 2, "checkpoint": "checkpoints/iter_0002"})
    )
    Population().save(run / "population.json")
    compact(run)
    assert [f.name for f in (run / "checkpoints").iterdir()] == ["iter_0002"]
    assert sorted(f.name for f in (run / "checkpoints" / "iter_0002").iterdir()) == [
        "protagonist.zip"
    ]
    assert not (run / "tb").exists()
    lines = (run / "learning.csv").read_text().splitlines()
    assert lines == ["writer,tag,step,value", "protagonist_0,train/critic_loss,100,2.5"]
