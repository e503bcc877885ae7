"""Installable as a library: ranges in the metadata, one extra per family, the lock, and the
core wheel alone in a fresh virtual environment (no extras) running a game, a training
iteration and an evaluation, with a clear error for every family whose extra is missing."""

from __future__ import annotations

import importlib.metadata
import json
import re
import subprocess
import sys
import venv
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.version import Version

import advgame
from advgame.core.registry import ScenarioSpec, scenario_spec
from advgame.errors import MissingExtraError

ROOT = Path(advgame.__file__).resolve().parents[1]
LOCK = ROOT / "constraints.txt"
CORE = {"gymnasium", "pettingzoo", "mujoco", "torch", "stable-baselines3", "numpy"}
CORE |= {"matplotlib", "tqdm", "tensorboard"}
EXTRAS = {"box2d", "mamujoco", "robotics", "robosuite", "llm", "ray", "test", "all", "bench"}


def _lock() -> dict[str, Version]:
    pins = {}
    for line in LOCK.read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            req = Requirement(line)
            (spec,) = req.specifier
            assert spec.operator == "==", line
            pins[_norm(req.name)] = Version(spec.version)
    return pins


def _norm(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def _requirements() -> list[Requirement]:
    return [Requirement(r) for r in importlib.metadata.requires("advgame") or []]


def test_metadata_declares_ranges_not_pins() -> None:
    meta = importlib.metadata.metadata("advgame")
    assert meta["Requires-Python"] == ">=3.11"
    core = [r for r in _requirements() if r.marker is None]
    assert {_norm(r.name) for r in core} == CORE
    for req in core:
        operators = {s.operator for s in req.specifier}
        assert ">=" in operators and "==" not in operators, req  # lower-bounded, never pinned
    assert set(meta.get_all("Provides-Extra") or []) == EXTRAS


def test_lock_pins_every_requirement_inside_its_range() -> None:
    pins = _lock()
    assert str(pins["torch"]) == "2.13.0"  # the CPU wheel on local disk; a range pulls CUDA
    for req in _requirements():
        if _norm(req.name) == "advgame":  # the `all` extra names advgame's own extras
            continue
        assert _norm(req.name) in pins, f"{req} is not in constraints.txt"
        assert req.specifier.contains(pins[_norm(req.name)], prereleases=True), (req, pins)


def test_readme_installation_names_every_extra_and_the_python_versions() -> None:
    text = (ROOT / "README.md").read_text()
    section = text[text.index("## Installation") :]
    section = section[: section.index("\n## ", 1)]
    for extra in EXTRAS:
        assert f"`{extra}`" in section, extra
    assert "Python 3.11" in section and "constraints.txt" in section


def test_a_missing_extra_is_a_clear_error_and_is_marked_in_the_listing(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from advgame.cli import main
    from advgame.core import registry

    spec = ScenarioSpec(
        id="Needs-v0",
        task="advgame.scenarios.mujoco:make_task",
        presets="advgame.scenarios.mujoco:presets",
        family="exotic",
        extra="exotic",
        requires=("advgame_no_such_simulator",),
    )
    scenario_spec("Hopper-v5")  # the built-ins are registered before the temporary entry
    monkeypatch.setitem(registry._REGISTRY, spec.id, spec)
    with pytest.raises(MissingExtraError, match=r'pip install "advgame\[exotic\]"'):
        advgame.make("Needs-v0")
    assert main(["list", "Needs-v0", "Hopper-v5"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert 'needs: pip install "advgame[exotic]"' in lines[0]
    assert "needs" not in lines[1]


def test_every_family_beyond_the_core_names_an_extra() -> None:
    for sid in advgame.list_scenarios():
        spec = scenario_spec(sid)
        if spec.family not in ("mujoco", "safe"):  # Gymnasium's MuJoCo tasks: the core install
            assert spec.extra in EXTRAS and spec.requires, sid
        assert spec.missing() == [], f"{sid}: the locked install lacks {spec.missing()}"


CORE_SCRIPT = """
import json
import advgame
from advgame.errors import MissingExtraError
from advgame.evaluation import EvalJob, evaluate
from advgame.training import TrainConfig, train

game = advgame.make("Hopper-v5", preset="default")
obs, _ = game.reset(seed=0)
steps = 0
while game.agents and steps < 20:
    game.step({a: game.action_space(a).sample() for a in game.agents})
    steps += 1
config = TrainConfig(scenario="Hopper-v5", preset="atla", iterations=1, protagonist_steps=64,
                     adversary_steps=64, protagonist_hparams={"n_steps": 64, "batch_size": 32},
                     adversary_hparams={"n_steps": 64, "batch_size": 32})
run = train(config, "run", progress=False)
job = EvalJob(scenario="Hopper-v5", protagonist="zero", protagonist_spec=lambda o: [0.0] * 3,
              adversary="nominal", seeds=(0,), make_kwargs={"preset": "default"})
table = evaluate([job], workers=1, progress=False)
errors = {}
for sid in ("LunarLander-v3", "MA-HalfCheetah-2x3", "RS-Lift"):
    try:
        advgame.make(sid)
    except MissingExtraError as exc:
        errors[sid] = str(exc)
import importlib.util
print(json.dumps({"steps": steps, "trained": (run / "state.json").is_file(), "rows": len(table.rows),
                  "errors": errors,
                  "absent": [m for m in ("Box2D", "gymnasium_robotics", "robosuite", "supersuit")
                             if importlib.util.find_spec(m) is None]}))
"""


def test_core_wheel_alone_runs_in_a_fresh_venv(tmp_path: Path) -> None:
    """The wheel of advgame without extras, installed with the lock's versions, runs the core."""
    wheels = tmp_path / "wheels"
    build = [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(wheels), str(ROOT)]
    subprocess.run(build, check=True, capture_output=True, timeout=300)
    (wheel,) = wheels.glob("advgame-*.whl")
    env_dir = tmp_path / "venv"
    venv.create(env_dir, with_pip=True)
    python = env_dir / "bin" / "python"
    install = [str(python), "-m", "pip", "install", "-q", "-c", str(LOCK), str(wheel)]
    proc = subprocess.run(install, capture_output=True, text=True, timeout=900, check=False)
    assert proc.returncode == 0, proc.stderr[-3000:]
    work = tmp_path / "work"
    work.mkdir()
    proc = subprocess.run(
        [str(python), "-c", CORE_SCRIPT], cwd=work, capture_output=True, text=True, timeout=600
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["absent"] == ["Box2D", "gymnasium_robotics", "robosuite", "supersuit"]
    assert out["steps"] > 0 and out["trained"] and out["rows"] == 1
    assert 'pip install "advgame[box2d]"' in out["errors"]["LunarLander-v3"]
    assert 'pip install "advgame[mamujoco]"' in out["errors"]["MA-HalfCheetah-2x3"]
    assert 'pip install "advgame[robosuite]"' in out["errors"]["RS-Lift"]
    listing = subprocess.run(
        [str(env_dir / "bin" / "advgame"), "list", "LunarLander-v3", "Hopper-v5"],
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    ).stdout.splitlines()
    assert "advgame[box2d]" in listing[0] and "needs" not in listing[1]
