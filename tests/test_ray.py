"""Jobs on Ray core and on the local pool: same numbers, retried dead workers, kept results.

One local Ray (2 CPUs) serves the whole module. The job functions below live at module level;
workers import this module by name (``tests.test_ray``), so its root goes on their path.
"""

from __future__ import annotations

import json
import os
import signal
import zipfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from advgame.agents.common.checkpoint import SB3Checkpoint
from advgame.core.policy import ConstantPolicy
from advgame.errors import ConfigError
from advgame.evaluation import budget_sweep, evaluate
from advgame.runner.run import JobFailedError, run_units

ray = pytest.importorskip("ray", reason="the ray extra: pip install -c constraints.txt '.[ray]'")

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def local_ray() -> Iterator[None]:
    env = {"PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}
    ray.init(num_cpus=2, include_dashboard=False, runtime_env={"env_vars": env})
    yield
    ray.shutdown()


@pytest.fixture
def importable(monkeypatch: pytest.MonkeyPatch) -> None:
    """Local pool workers import this module by name: put its root on the path."""
    monkeypatch.syspath_prepend(str(ROOT))


def _table_jobs() -> list:
    still = ConstantPolicy(np.zeros(3, dtype=np.float32))
    return budget_sweep("Hopper-v5", {"still": still}, [0.0, 0.2], seeds=(0, 1, 2),
                        make_kwargs={"max_episode_steps": 40})  # fmt: skip


def die_once(folder: str) -> int:
    """Kill this worker process on the first attempt (a marker file remembers it)."""
    marker = Path(folder) / "attempted"
    with marker.open("a") as f:
        f.write(f"{os.getpid()}\n")
    if len(marker.read_text().split()) == 1:
        os.kill(os.getpid(), signal.SIGKILL)
    return os.getpid()


def always_die(folder: str) -> int:
    """Kill this worker process on every attempt."""
    Path(folder, f"try-{os.getpid()}").touch()
    os.kill(os.getpid(), signal.SIGKILL)
    return 0


def count_calls(unit: tuple[str, int]) -> int:
    """Append to a log (to count calls) and return the unit's number squared."""
    folder, n = unit
    with Path(folder, "calls").open("a") as f:
        f.write(f"{n}\n")
    return n * n


def still_hopper(obs: np.ndarray) -> np.ndarray:
    """A Hopper protagonist that does nothing (it falls, so episodes are short)."""
    return np.zeros(3, dtype=np.float32)


def fail(unit: tuple[str, str]) -> int:
    """Raise the error the unit names (or return 1 for "ok"), logging each attempt."""
    folder, kind = unit
    with Path(folder, "tries").open("a") as f:
        f.write(kind[0])
    if kind == "ok":
        return 1
    raise {"config": ConfigError, "runtime": RuntimeError}[kind](f"{kind} trouble")


def fingerprint(spec: SB3Checkpoint) -> tuple[int, float]:
    """This worker's pid and the sum of the weights of the model it has for `spec`."""
    from advgame.agents.common.checkpoint import load_model

    params = load_model(spec.path, spec.algo).policy.parameters()
    return os.getpid(), float(sum(p.detach().sum() for p in params))


def file_size(spec: SB3Checkpoint) -> tuple[str, int]:
    """Where the worker found the spec's file, and its size."""
    return spec.path, Path(spec.path).stat().st_size


# -- Ray ------------------------------------------------------------------------------------
def test_ray_gives_the_numbers_of_the_local_pool(
    local_ray: None, importable: None, tmp_path: Path
) -> None:
    jobs = _table_jobs()
    here = evaluate(jobs, workers=1, progress=False)
    pooled = evaluate(jobs, workers=2, progress=False)
    on_ray = evaluate(jobs, workers=2, progress=False, executor="ray", results_dir=tmp_path)
    assert len(here.rows) == 2 * 3 and len({r["true_return"] for r in here.rows}) > 1
    assert on_ray.rows == pooled.rows == here.rows
    timings = [json.loads(line) for line in (tmp_path / "jobs.jsonl").read_text().splitlines()]
    assert len(timings) == 6 and all(t["attempts"] == 1 and t["error"] is None for t in timings)
    assert all(0 < t["startup_s"] <= t["end"] - t["start"] for t in timings)
    assert len({t["pid"] for t in timings}) <= 2  # warm: two worker processes serve six jobs


def test_a_killed_ray_worker_is_retried(local_ray: None, tmp_path: Path) -> None:
    (rec,) = run_units(die_once, [str(tmp_path)], executor="ray", max_retries=1)
    pids = (tmp_path / "attempted").read_text().split()
    assert rec.attempts == 2 and rec.error is None and rec.value == int(pids[1]) != int(pids[0])


def test_a_job_failing_every_attempt_is_reported_not_dropped(
    local_ray: None, tmp_path: Path
) -> None:
    with pytest.raises(JobFailedError, match=r"1 job\(s\) failed") as info:
        run_units(always_die, [str(tmp_path)], executor="ray", max_retries=1)
    assert len(info.value.failures) == 1 and "Worker" in info.value.failures[0][1]
    assert len(list(tmp_path.glob("try-*"))) == 2  # one attempt and one retry, no more


def test_checkpoints_travel_as_bytes_to_ray_workers(local_ray: None, tmp_path: Path) -> None:
    ckpt = tmp_path / "model.zip"
    ckpt.write_bytes(b"x" * 1234)
    spec = SB3Checkpoint(str(ckpt))
    (shipped,) = run_units(file_size, [spec], executor="ray")
    (shared,) = run_units(file_size, [spec], executor="ray", ship_files=False)
    assert shipped.value[1] == 1234 and shipped.value[0] != str(ckpt)  # a node-local copy
    assert shared.value == (str(ckpt), 1234)


def test_the_cli_evaluates_on_ray_with_the_same_table(
    local_ray: None, importable: None, tmp_path: Path
) -> None:
    from advgame.cli import main

    args = [
        "evaluate",
        "--scenario",
        "Hopper-v5",
        "--callable",
        "still=tests.test_ray:still_hopper",
    ]
    args += ["--adversaries", "nominal", "preset:state-gauss-0.1", "--budgets", "0.2"]
    args += ["--seeds", "2", "--workers", "2"]
    assert main([*args, "--out", str(tmp_path / "local")]) == 0
    assert main([*args, "--out", str(tmp_path / "ray"), "--executor", "ray"]) == 0
    for name in ("payoff.csv", "budget.csv"):
        local = (tmp_path / "local" / name).read_text()
        assert local.count("\n") == 1 + 2 * (2 if name == "payoff.csv" else 1)  # header, rows
        assert local == (tmp_path / "ray" / name).read_text()


def test_psro_on_ray_equals_psro_here(local_ray: None, tmp_path: Path) -> None:
    from advgame.workflows.psro import PSROConfig, load_meta, run_psro

    cfg = PSROConfig(scenario="InvertedPendulum-v5", preset="rarl", iterations=1,
                     protagonist_steps=128, adversary_steps=128, protagonist_hparams={"n_steps": 64},
                     adversary_hparams={"n_steps": 64}, eval_seeds=2, max_episode_steps=40)  # fmt: skip
    here = run_psro(cfg, tmp_path / "here")
    on_ray = run_psro(cfg, tmp_path / "ray", executor="ray", workers=2)
    meta = load_meta(on_ray)
    assert [m["iteration"] for m in meta] == [0, 1] and len(meta[1]["matrix"]) == 2
    assert meta == load_meta(here)
    # the checkpoints came back from the workers as bytes: the same weights
    for name in ("protagonist_1/protagonist.zip", "force_adversary_1/force_adversary.zip"):
        weights = [
            zipfile.ZipFile(run / "checkpoints" / name).read("policy.pth") for run in (here, on_ray)
        ]
        assert weights[0] == weights[1] and len(weights[0]) > 1000


# -- the local pool, same guarantees --------------------------------------------------------
def test_a_killed_pool_worker_is_retried(importable: None, tmp_path: Path) -> None:
    units = [str(tmp_path / "a"), str(tmp_path / "b")]
    for u in units:
        Path(u).mkdir()
    recs = run_units(die_once, units, workers=2, max_retries=2)
    assert all(r.error is None and r.value > 0 for r in recs)
    assert all(len(Path(u, "attempted").read_text().split()) == 2 for u in units)


def test_warm_pool_workers_reload_a_rewritten_checkpoint(importable: None, tmp_path: Path) -> None:
    import gymnasium as gym
    from stable_baselines3 import PPO

    spec = SB3Checkpoint(str(tmp_path / "model.zip"))
    weights = []
    for seed in (1, 2):  # the same path, another model
        PPO("MlpPolicy", gym.make("Pendulum-v1"), seed=seed, device="cpu").save(spec.path)
        os.utime(spec.path, ns=(seed * 10**9, seed * 10**9))  # distinct mtimes, however fast
        recs = run_units(fingerprint, [spec, spec, spec, spec], workers=2)
        weights.append({r.value[1] for r in recs})
        pids = {r.value[0] for r in recs}
    assert len(weights[0]) == len(weights[1]) == 1 and weights[0] != weights[1]
    assert os.getpid() not in pids and len(pids) <= 2


def test_finished_units_are_never_recomputed(importable: None, tmp_path: Path) -> None:
    units = [(str(tmp_path), n) for n in range(5)]
    parts = tmp_path / "parts"
    first = run_units(count_calls, units[:3], workers=2, parts_dir=parts)
    again = run_units(count_calls, units, workers=2, parts_dir=parts)
    assert [r.value for r in again] == [0, 1, 4, 9, 16] and [r.value for r in first] == [0, 1, 4]
    calls = sorted(int(n) for n in (tmp_path / "calls").read_text().split())
    assert calls == [0, 1, 2, 3, 4]  # units 0-2 ran once, in the first call only
    assert [r.attempts for r in again] == [0, 0, 0, 1, 1]


@pytest.mark.parametrize("workers", [1, 2])
def test_errors_a_user_made_are_raised_at_once_others_retried(
    importable: None, tmp_path: Path, workers: int
) -> None:
    with pytest.raises(ConfigError, match="config trouble"):
        run_units(fail, [(str(tmp_path), "config")], workers=workers, max_retries=3)
    assert (tmp_path / "tries").read_text() == "c"  # an AdvgameError is not retried
    (tmp_path / "tries").unlink()
    units = [(str(tmp_path), "runtime"), (str(tmp_path), "ok")]
    with pytest.raises(JobFailedError, match="RuntimeError: runtime trouble") as info:
        run_units(fail, units, workers=workers, max_retries=2, parts_dir=tmp_path / "parts")
    assert sorted((tmp_path / "tries").read_text()) == ["o", "r", "r", "r"]
    assert [u for u, _ in info.value.failures] == units[:1]
    assert len(list((tmp_path / "parts").glob("*.pkl"))) == 1  # the good unit is kept


def test_executor_arguments_are_checked() -> None:
    with pytest.raises(ConfigError, match='Did you mean "ray"'):
        run_units(count_calls, [], executor="rya")
    with pytest.raises(ConfigError, match="max_retries"):
        run_units(count_calls, [], max_retries=-1)
