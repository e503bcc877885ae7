"""Times of the README's two set-up commands in a fresh clone, between two calibrations.

Clones the repository's HEAD (committed files only) into a temporary folder and runs there the
two lines of the README's first ```bash block, as a new user would. Each line is a chain of
``&&`` steps; each step is timed on its own, so the installs are told apart from the demo and
from the test suite. `benchmarks/calibrate.py` runs before and after, so that every time can be
read against the machine's speed that day (the README quotes its times for about 35 µs per raw
HalfCheetah-v5 step). The steps run with this environment minus any active virtual
environment; ``PYTHONDONTWRITEBYTECODE`` is reported because, where it is set, every fresh
process compiles its imports again, which slows the suite's subprocesses and workers.
The clone is deleted at the end unless ``--keep``.

Run: ``python benchmarks/fresh_clone_times.py`` (about 20 minutes on two cores; ``--dry-run``
prints the steps without running them, ``--json FILE`` also writes the record).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from calibrate import line, step_us

ROOT = Path(__file__).resolve().parents[1]
KINDS = {"-m venv": "venv", "pip install": "install", "advgame demo": "demo", "pytest": "tests"}
"""A step's kind: the first of these keys found in it (else ``other``)."""


def setup_commands(readme: str) -> list[str]:
    """The non-empty lines of the first ```bash block of `readme` (the README's two commands)."""
    block = re.search(r"```bash\n(.*?)```", readme, flags=re.S)
    if block is None:
        raise ValueError("The README has no ```bash block; expected its two set-up commands.")
    return [text.strip() for text in block.group(1).splitlines() if text.strip()]


def steps(command: str) -> list[tuple[str, str]]:
    """`command` split at ``&&`` into ``(kind, step)`` pairs (kinds from `KINDS`)."""
    parts = [part.strip() for part in command.split("&&")]
    return [(next((k for key, k in KINDS.items() if key in p), "other"), p) for p in parts]


def calibration(steps_per_repeat: int, repeats: int = 5) -> float:
    """µs per raw HalfCheetah-v5 step now; printed as `calibrate.py` prints it."""
    load = os.getloadavg()[0]
    us = step_us(steps_per_repeat, repeats)
    print(line(us, steps_per_repeat, repeats, load), flush=True)
    return us


def _environment() -> dict[str, str]:
    """The environment of a new shell: this one without its virtual environment."""
    env = {k: v for k, v in os.environ.items() if k not in ("VIRTUAL_ENV", "PYTHONPATH")}
    if sys.prefix != sys.base_prefix:
        own = str(Path(sys.prefix) / "bin")
        env["PATH"] = os.pathsep.join(p for p in env.get("PATH", "").split(os.pathsep) if p != own)
    return env


def run_steps(commands: list[str], cwd: Path) -> list[dict[str, Any]]:
    """Run every step of `commands` in `cwd` with bash, in order, until one fails; their times."""
    env = _environment()
    record: list[dict[str, Any]] = []
    for number, command in enumerate(commands, 1):
        for kind, step in steps(command):
            print(f"[{number}] {kind}: {step}", flush=True)
            start = time.perf_counter()
            code = subprocess.run(["bash", "-c", step], cwd=cwd, env=env, check=False).returncode
            seconds = round(time.perf_counter() - start, 1)
            print(f"[{number}] {kind}: {seconds:.0f} s (exit {code})", flush=True)
            record.append({"line": number, "kind": kind, "seconds": seconds, "exit": code})
            if code != 0:
                return record
    return record


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repo", type=Path, default=ROOT, help="the repository to clone")
    parser.add_argument("--dry-run", action="store_true", help="print the steps, run nothing")
    parser.add_argument("--keep", action="store_true", help="keep the clone")
    parser.add_argument("--json", type=Path, help="also write the record to this file")
    parser.add_argument("--calibration-steps", type=int, default=20_000, help="per repeat")
    args = parser.parse_args(argv)
    commands = setup_commands((args.repo / "README.md").read_text())
    if args.dry_run:
        for number, command in enumerate(commands, 1):
            for kind, step in steps(command):
                print(f"[{number}] {kind}: {step}")
        return 0
    bytecode = os.environ.get("PYTHONDONTWRITEBYTECODE") or "unset"
    print(f"cores: {os.cpu_count()}; PYTHONDONTWRITEBYTECODE: {bytecode}")
    before = calibration(args.calibration_steps)
    folder = Path(tempfile.mkdtemp(prefix="advgame-clone-"))
    clone = folder / "advgame"
    subprocess.run(["git", "clone", "--quiet", str(args.repo), str(clone)], check=True)
    head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=clone, check=True,
                          capture_output=True, text=True).stdout.strip()  # fmt: skip
    print(f"clone of {head[:12]} in {clone}", flush=True)
    try:
        record = run_steps(commands, clone)
    finally:
        if not args.keep:
            shutil.rmtree(folder, ignore_errors=True)
    after = calibration(args.calibration_steps)
    for r in record:
        print(f"{r['seconds']:>8.0f} s  [{r['line']}] {r['kind']}")
    result = {"head": head, "calibration_us": [round(before, 1), round(after, 1)], "steps": record}
    if args.json:
        args.json.write_text(json.dumps(result, indent=2) + "\n")
    return next((int(r["exit"]) for r in record if r["exit"]), 0)


if __name__ == "__main__":
    sys.exit(main())
