"""Installable as a library: ranges in the metadata, one extra per family, the lock, and the
core wheel alone in a fresh virtual environment (no extras) running a game, a training
iteration and an evaluation, with a clear error for every family whose extra is missing."""

from __future__ import annotations

import importlib.metadata
import json
import os
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
CORE = {"gymnasium", "pettingzoo", "mujoco", "torch", "stable-baselines3", "sb3-contrib", "numpy"}
CORE |= {"matplotlib", "tqdm", "tensorboard"}
EXTRAS = {
    "box2d",
    "mamujoco",
    "robotics",
    "robosuite",
    "llm",
    "ray",
    "supersuit",
    "torchrl",
    "test",
    "all",
    "bench",
    "docs",
    "zoo",
}


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


def test_the_installation_page_names_every_extra_and_the_python_versions() -> None:
    text = (ROOT / "docs" / "getting-started.md").read_text()
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


def _build(hook: str, project: Path, out: Path) -> Path:
    """Run setuptools' PEP 517 `hook` (build_sdist or build_wheel) on `project` into `out`."""
    code = f"import sys; from setuptools import build_meta as b; print(b.{hook}(sys.argv[1]))"
    done = subprocess.run([sys.executable, "-c", code, str(out)], cwd=project, check=True,
                          capture_output=True, text=True, timeout=300)  # fmt: skip
    return out / done.stdout.strip().splitlines()[-1]


def _sdist_then_wheel(project: Path, out: Path) -> tuple[Path, Path]:
    """The sdist of `project`, and the wheel built from that sdist (as pip builds it)."""
    import tarfile

    sdist = _build("build_sdist", project, out)
    with tarfile.open(sdist) as tar:
        tar.extractall(out / "src", filter="data")
    (unpacked,) = (out / "src").iterdir()
    return sdist, _build("build_wheel", unpacked, out)


def test_core_wheel_alone_runs_in_a_fresh_venv(tmp_path: Path) -> None:
    """As a user installs it: advgame's wheel built from its sdist (which must hold everything
    the checkout's wheel has), and the zoo's wheel, in a fresh venv outside the checkout with
    the lock's versions and no extras, run the core, list the released agents and evaluate
    one; families without their extra say what to install.
    """
    sys.path.insert(0, str(ROOT / "zoo" / "package"))
    try:
        import build as zoo_package  # zoo/package/build.py
    finally:
        sys.path.pop(0)
    import zipfile

    dist, direct = tmp_path / "dist", tmp_path / "direct"
    dist.mkdir()
    direct.mkdir()
    _, wheel = _sdist_then_wheel(ROOT, dist)
    # the sdist holds everything the wheel is built from: both wheels have the same files
    names = [
        sorted(zipfile.ZipFile(w).namelist()) for w in (wheel, _build("build_wheel", ROOT, direct))
    ]
    assert names[0] == names[1]
    assert "advgame/evaluation/table/jobs.py" in names[0]  # every subpackage made it in
    assert any(n.startswith("advgame/adversaries/prompts/") for n in names[0])
    zoo_wheel = next(p for p in zoo_package.build(dist) if p.suffix == ".whl")
    env_dir = tmp_path / "venv"
    venv.create(env_dir, with_pip=True)
    python = env_dir / "bin" / "python"
    # --no-compile: pip's byte-compiling of torch and the rest took half of this test; what is
    # installed, and how it runs, is the same without it
    install = [
        str(python),
        "-m",
        "pip",
        "install",
        "-q",
        "--no-compile",
        "-c",
        str(LOCK),
        str(wheel),
        str(zoo_wheel),
    ]
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
    cli = str(env_dir / "bin" / "advgame")
    env = {k: v for k, v in os.environ.items() if k != "ADVGAME_ZOO"}

    def run(*argv: str) -> str:
        done = subprocess.run([cli, *argv], cwd=work, env=env, capture_output=True, text=True,
                              timeout=600, check=False)  # fmt: skip
        assert done.returncode == 0, done.stderr[-3000:]
        return done.stdout

    listing = run("list", "LunarLander-v3", "Hopper-v5").splitlines()
    assert "advgame[box2d]" in listing[0] and "needs" not in listing[1]
    zoo = run("zoo", "list").splitlines()
    from advgame.workflows.zoo import entries

    released = len(entries(ROOT / "zoo"))  # what the package was built from: the checkout's zoo
    assert released >= 21 and len(zoo) == 1 + released, zoo  # from the installed package
    assert any(line.startswith("hopper/ppo ") for line in zoo), zoo
    report = run("evaluate", "--zoo", "hopper/ppo", "--seeds", "1", "--adversaries", "nominal",
                 "--budgets", "--out", "eval")  # fmt: skip
    assert "report:" in report and (work / "eval" / "payoff.csv").is_file()
    # the families whose extra the core install has: Gymnasium's MuJoCo tasks and safe tasks
    imports = "import advgame.scenarios.mujoco, advgame.scenarios.safety; print('ok')"
    assert run_python(python, imports, work) == "ok"


def run_python(python: Path, code: str, cwd: Path) -> str:
    """`code` run by the venv's `python` in `cwd`; its last line of output."""
    done = subprocess.run([str(python), "-c", code], cwd=cwd, capture_output=True, text=True,
                          timeout=300, check=True)  # fmt: skip
    return done.stdout.strip().splitlines()[-1]
