"""``advgame evaluate``: who is evaluated, against which adversary columns, where jobs run."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

__all__ = ["evaluate_parser", "executor_arguments"]


def executor_arguments(p: argparse.ArgumentParser, workers: int) -> None:
    """Where jobs run (`advgame.runner.run`)."""
    p.add_argument("--workers", type=int, default=workers,
                   help=f"local worker processes, or the CPUs of a local Ray (default {workers})")  # fmt: skip
    p.add_argument("--executor", choices=("local", "ray"), default="local",
                   help="run jobs in a local process pool (default) or as Ray tasks (advgame[ray])")  # fmt: skip
    p.add_argument("--address", help="Ray cluster address (e.g. auto, ray://head:10001); default: "
                   "a local Ray started for this command")  # fmt: skip


def _cmd_evaluate(args: argparse.Namespace) -> int:
    from advgame.evaluation import use_executor

    with use_executor(args.executor, args.address):
        return _evaluate(args)


def _evaluate(args: argparse.Namespace) -> int:
    from advgame.errors import ConfigError
    from advgame.workflows import zoo
    from advgame.workflows.suite import BUDGETS, evaluate_runs

    if args.exploitability < 0:
        raise ConfigError(
            f"--exploitability is the optimal attack's steps per candidate, >= 0 (0: no "
            f"search); got {args.exploitability}."
        )

    released, own, threat = zoo.evaluation_inputs(
        args.zoo or [], adversaries=args.zoo_adversaries, threat=args.threat
    )
    out = evaluate_runs(
        args.runs,
        Path(args.out),
        seeds=args.seeds,
        episodes=args.episodes,
        workers=args.workers,
        exploitability_steps=args.exploitability,
        checkpoints=args.checkpoint or [],
        callables=args.callable or [],
        scenario=args.scenario,
        normalizers=args.normalizer or [],
        raw_obs=args.raw_obs or [],
        teams=args.team or [],
        adversaries=args.adversaries or ["default"],
        last=args.last,
        sample=args.sample,
        seed=args.seed,
        budgets=BUDGETS if args.budgets is None else args.budgets,
        threat=threat,
        released=released,
        released_adversaries=own,
        progress=not args.no_progress,
    )
    print(f"report: {out}")
    return 0


_COLUMN_HELP = (
    "nominal",
    "preset:NAME",
    "random (the paper's random presets)",
    "scheduled",
    "learned[:RUN_DIR] (latest learned snapshot; no RUN_DIR: of every evaluated run)",
    "population:RUN_DIR|FILE[,last=K|,sample=K][,preset=NAME] (one column per snapshot)",
    "attack:random|mad|critic|rs|max-cost|pa-ad (noise in the threat model's observation "
    "budget, or a white-box attack on each protagonist's own networks; rs, max-cost and pa-ad "
    "first learn a critic or a director per protagonist, cached)",
    "attacks = attack:random attack:mad attack:critic attack:rs learned (the worst-of-attacks "
    "suite)",
    "default = nominal random scheduled learned",
)


def _evaluate_arguments(p: argparse.ArgumentParser) -> None:
    """Who is evaluated, and against whom (see `advgame.workflows.suite.evaluate_runs`)."""
    p.add_argument(
        "runs", nargs="*", help="run directories whose final protagonists join the evaluation"
    )
    p.add_argument("--scenario", help="the scenario to play (default: the runs' scenario)")
    for flag, metavar, text in (
        (
            "--checkpoint",
            "NAME=PATH[:ALGO]",
            "an SB3 model as a protagonist (ALGO: ppo, sac, td3, ompo, dbc, rsc, recurrent-ppo; default ppo)",
        ),
        ("--normalizer", "NAME=PATH", "its VecNormalize pickle or obs-norm .npz"),
        ("--raw-obs", "NAME", "checkpoint NAME was trained on raw observations (no normalizer)"),
        ("--callable", "NAME=MODULE:FUNCTION", "a plain function obs -> action as a protagonist"),
        ("--team", "NAME=PATH", "a MAPPO/IPPO <algo>_actors.pt as a protagonist team"),
        ("--zoo", "ID", "a released zoo agent (advgame zoo list), e.g. hopper/ppo"),
    ):
        p.add_argument(flag, action="append", metavar=metavar, help=f"{text} (repeatable)")
    p.add_argument(
        "--zoo-adversaries",
        action="store_true",
        help="add the 'attack optimal' column: each --zoo agent against its released adversary",
    )
    p.add_argument(
        "--adversaries",
        nargs="+",
        metavar="SPEC",
        help="adversary columns (default: 'default'); nominal is always played",
    )
    group = p.add_mutually_exclusive_group()
    group.add_argument("--last", type=int, metavar="K", help="population columns: last K only")
    group.add_argument("--sample", type=int, metavar="K", help="population columns: K drawn")
    p.add_argument("--seed", type=int, default=0, help="seed of --sample (default 0)")
    p.add_argument(
        "--threat",
        metavar="PRESET",
        help="the table's one threat model: the preset every attack, learned and best-response "
        "column plays in (default: atla where the scenario has it, else default)",
    )
    p.add_argument(
        "--budgets",
        nargs="*",
        type=float,
        metavar="SIGMA",
        help="state-noise σ of the budget sweep (default 0 0.05 0.1 0.15; none: no sweep)",
    )


def evaluate_parser(sub: Any) -> None:
    """``advgame evaluate``: protagonists, adversary columns, seeds, executor."""
    p = sub.add_parser(
        "evaluate",
        help="evaluate fixed policies against chosen adversary columns",
        description="Play every protagonist against every adversary column (payoff table, "
        "metrics, budget sweep, report). Adversary column specs: " + "; ".join(_COLUMN_HELP),
    )
    _evaluate_arguments(p)
    p.add_argument("--out", required=True, help="output folder (CSV, JSON, plots, report.md)")
    p.add_argument("--seeds", type=int, default=3, help="evaluation seeds per cell (default 3)")
    p.add_argument("--episodes", type=int, default=1, help="episodes per seed (default 1)")
    executor_arguments(p, workers=2)
    p.add_argument("--no-progress", action="store_true", help="no progress bars or log lines")
    p.add_argument(
        "--exploitability",
        type=int,
        default=0,
        metavar="STEPS",
        help="the learned optimal attack: per protagonist (runs, checkpoints, teams, callables), "
        "train one PPO observation adversary per point of a small hyper-parameter grid for "
        "STEPS steps each in the threat model, keep the strongest as the 'attack optimal' "
        "column, and report the exploitability (nominal minus its return)",
    )
    p.set_defaults(func=_cmd_evaluate)
