"""The ``advgame`` command: list scenarios, train, resume, evaluate, psro, report, and the demo.

Run ``advgame --help`` or ``advgame COMMAND --help``.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from advgame.cli.campaign import campaign_parser, zoo_parser
from advgame.cli.evaluate import evaluate_parser, executor_arguments
from advgame.core.library_logs import quiet_libraries
from advgame.errors import AdvgameError, ConfigError

__all__ = ["main"]

log = logging.getLogger("advgame")

EPILOG = """examples:
  advgame list --presets Hopper-v5
  advgame train --method atla --scenario Hopper-v5 --iterations 5 --run-dir runs/atla
  advgame train --config runs/atla/config.json --set iterations=20 --run-dir runs/atla20
  advgame resume runs/atla
  advgame evaluate runs/ppo runs/atla --out results/hopper --seeds 3
  advgame evaluate --scenario Hopper-v5 --checkpoint mine=model.zip:ppo \
      --normalizer mine=vecnormalize.pkl \
      --adversaries preset:state-gauss-0.1 population:runs/atla --last 5 --out results/mine
  advgame evaluate runs/atla --out results/ray --executor ray --address auto
  advgame psro --scenario Hopper-v5 --preset rarl --iterations 3 --solver nash --run-dir runs/psro
  advgame psro --run-dir runs/psro --resume --executor ray
  advgame report results/hopper
  advgame demo
"""


def _cmd_list(args: argparse.Namespace) -> int:
    from advgame.core.registry import list_scenarios, scenario_spec

    ids = args.ids or list_scenarios(args.family)
    for sid in ids:
        spec = scenario_spec(sid)
        absent = spec.missing()
        note = f'  [needs: pip install "advgame[{spec.extra}]"]' if absent else ""
        print(f"{sid:28s} {spec.family:8s} {spec.description}{note}")
        if args.presets and not absent:
            for name, preset in sorted(spec.load_presets().items()):
                print(f"    {name:24s} {preset.description}")
    return 0


def _train_config(args: argparse.Namespace) -> Any:
    from advgame.core.config import from_dict, load_json, override, to_dict
    from advgame.training import METHODS, TrainConfig

    cfg = load_json(TrainConfig, args.config) if args.config else TrainConfig()
    data = to_dict(cfg)
    if args.method:
        data.update(METHODS[args.method])
    for name in data:
        value = getattr(args, name, None)
        if value is not None:
            data[name] = value
    for item in getattr(args, "adversary", None) or []:
        agent, sep, spec = item.partition("=")
        if not sep or not agent:
            raise ConfigError(
                f"--adversary {item!r} is not AGENT=SPEC (e.g. action_adversary=gauss:0.1)."
            )
        try:
            parsed = json.loads(spec) if spec.lstrip().startswith("{") else spec
        except json.JSONDecodeError as exc:
            raise ConfigError(
                f"--adversary {item!r}: the spec is not valid JSON ({exc})."
            ) from None
        data["adversaries"] = {**(data.get("adversaries") or {}), agent: parsed}
    learned = data.get("learned")
    fixed = set(data.get("adversaries") or {})
    if learned and fixed & set(learned):
        raise ConfigError(
            f"Adversaries {sorted(fixed & set(learned))} are both fixed (--adversary) and learned."
        )
    return override(from_dict(TrainConfig, data), args.set or [])


def _cmd_train(args: argparse.Namespace) -> int:
    from advgame.training import train

    cfg = _train_config(args)
    run_dir = Path(args.run_dir or f"runs/{cfg.scenario}-{args.method or 'custom'}-s{cfg.seed}")
    train(cfg, run_dir, progress=not args.no_progress)
    print(f"run written to {run_dir}")
    return 0


def _cmd_resume(args: argparse.Namespace) -> int:
    from advgame.training import resume

    resume(args.run_dir, progress=not args.no_progress)
    print(f"run completed in {args.run_dir}")
    return 0


def _cmd_psro(args: argparse.Namespace) -> int:
    from advgame.core.config import from_dict, override, to_dict
    from advgame.workflows.psro import PSROConfig, resume_psro, run_psro

    where = {"executor": args.executor, "workers": args.workers, "address": args.address,
             "progress": not args.no_progress}  # fmt: skip
    if args.resume:
        resume_psro(args.run_dir, **where)
    else:
        data = to_dict(PSROConfig())
        data.update({k: getattr(args, k) for k in data if getattr(args, k, None) is not None})
        run_psro(override(from_dict(PSROConfig, data), args.set or []), args.run_dir, **where)
    print(f"PSRO run in {args.run_dir}; meta-game: {Path(args.run_dir) / 'report.md'}")
    return 0


def _cmd_report(args: argparse.Namespace) -> int:
    from advgame.workflows.suite import report_folder

    print(f"report: {report_folder(Path(args.folder))}")
    return 0


def _cmd_demo(args: argparse.Namespace) -> int:
    from advgame.workflows import zoo
    from advgame.workflows.demo import demo, demo_safe, demo_zoo, safe_summary, zoo_summary

    out = Path(args.out)
    why = zoo.missing()
    if why is not None:  # the two tables of released agents need the zoo: say so, go on
        print(f"skipping the released Hopper-v5 and SafetyHopper-v5 tables: {why}")
    zoo_report = demo_zoo(out / "zoo", quick=args.quick, workers=args.workers)
    if zoo_report is not None:
        print(zoo_summary(zoo_report.parent))
        print(f"zoo report: {zoo_report}")
    elif why is None:
        print(f"skipping the released Hopper-v5 table: {zoo.default_root()} has no Hopper-v5 "
              "agent released with an adversary")  # fmt: skip
    safe_report = demo_safe(out / "safe", quick=args.quick, workers=args.workers)
    if safe_report is not None:
        print(safe_summary(safe_report.parent))
        print(f"safe report: {safe_report}")
    elif why is None:
        print(f"skipping the released SafetyHopper-v5 table: {zoo.default_root()} has none")
    print(f"report: {demo(out, quick=args.quick, workers=args.workers)}")
    return 0


def _train_parser(sub: Any) -> None:
    """``advgame train``: every `TrainConfig` field is an option."""
    from advgame.core.config import add_arguments, field_docs, scalar_field
    from advgame.training import METHODS, TrainConfig

    p = sub.add_parser(
        "train",
        help="train a protagonist against learned adversaries",
        description="Alternate protagonist and adversary training (ATLA/RARL).",
    )
    p.add_argument(
        "--method",
        choices=sorted(METHODS),
        help="start from a named method: " + "; ".join(f"{k}: {v}" for k, v in METHODS.items()),
    )
    p.add_argument("--config", help="a config.json to start from (e.g. from another run)")
    p.add_argument(
        "--adversary",
        action="append",
        metavar="AGENT=SPEC",
        help="a fixed (not learned) adversary: gauss:STD, uniform:W, constant:V, random, zero, "
        "mad, critic, rs, llm, or a JSON dict with 'kind' (advgame.adversaries.specs); repeat "
        "for several agents",
    )
    p.add_argument(
        "--run-dir", help="where the run is written (default runs/<scenario>-<method>-s<seed>)"
    )
    p.add_argument(
        "--set",
        action="append",
        metavar="KEY=VALUE",
        help='override any config field with a JSON value, e.g. --set protagonist_hparams=\'{"n_steps": '
        "512}'. Fields without their own flag: "
        + "; ".join(
            f"{name}: {doc}"
            for name, doc in field_docs(TrainConfig).items()
            if not scalar_field(TrainConfig, name)
        ),
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar or log lines")
    add_arguments(p, TrainConfig)
    p.set_defaults(func=_cmd_train)


def _psro_parser(sub: Any) -> None:
    """``advgame psro``: every `PSROConfig` field is an option."""
    from advgame.core.config import add_arguments
    from advgame.workflows.psro import PSROConfig

    p = sub.add_parser(
        "psro",
        help="population training, PSRO-style: best responses and payoffs as jobs",
        description="Each iteration trains a protagonist best response to the adversaries' "
        "meta-strategy and an adversary best response to the protagonists' (as parallel jobs), "
        "evaluates the new payoff entries, and solves the meta-game (uniform, fictitious, nash).",
    )
    p.add_argument("--run-dir", required=True, help="the run directory")
    p.add_argument("--resume", action="store_true", help="continue the run in --run-dir")
    p.add_argument("--no-progress", action="store_true", help="no log line per iteration")
    p.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override a config field with a JSON value (e.g. protagonist_hparams)")  # fmt: skip
    executor_arguments(p, workers=1)
    add_arguments(p, PSROConfig)
    p.set_defaults(func=_cmd_psro)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``advgame`` (exposed for documentation and tests)."""
    parser = argparse.ArgumentParser(
        prog="advgame",
        description="Robust RL as adversarial PettingZoo games.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log at INFO level")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("list", help="list scenarios (and their presets)")
    p.add_argument("ids", nargs="*", help="scenario ids (default: all)")
    p.add_argument("--family", help="only this family (mujoco, box2d, ...)")
    p.add_argument("--presets", action="store_true", help="also list each scenario's presets")
    p.set_defaults(func=_cmd_list)
    _train_parser(sub)
    p = sub.add_parser("resume", help="continue an interrupted run")
    p.add_argument("run_dir", help="the run directory")
    p.add_argument("--no-progress", action="store_true", help="no progress bar or log lines")
    p.set_defaults(func=_cmd_resume)

    evaluate_parser(sub)
    campaign_parser(sub, executor_arguments)
    zoo_parser(sub)
    _psro_parser(sub)
    p = sub.add_parser("report", help="rebuild the report (Markdown + PNG) of an evaluation folder")
    p.add_argument("folder", help="a folder written by `advgame evaluate` or `advgame demo`")
    p.set_defaults(func=_cmd_report)

    p = sub.add_parser(
        "demo",
        help="the released Hopper agents under attack; PPO and ATLA-PPO trained briefly, evaluated",
    )
    p.add_argument("--out", default="reports/demo", help="output folder (default reports/demo)")
    p.add_argument("--quick", action="store_true", help="a much shorter run (for smoke tests)")
    p.add_argument("--workers", type=int, default=2, help="evaluation worker processes")
    p.set_defaults(func=_cmd_demo)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``advgame`` command; returns the exit status.

    An `AdvgameError` (a bad value or a damaged file) or an `OSError` (a path the system
    refuses) is printed as one line on stderr, with exit status 2; argparse's usage errors
    exit 2 too.
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
    )
    quiet_libraries(not args.verbose)  # robosuite's line per env: only with -v, and once
    try:
        return int(args.func(args))
    except AdvgameError as exc:
        print(f"advgame {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # e.g. `advgame list | head`
        sys.stderr.close()
        return 0
    except OSError as exc:  # a path the system refuses (a file where a folder goes, no rights)
        print(
            f"advgame {args.command}: error: {exc}; check that path and its permissions.",
            file=sys.stderr,
        )
        return 2
    except KeyboardInterrupt:
        print(
            f"advgame {args.command}: interrupted; a training run can be continued with "
            "`advgame resume RUN_DIR`.",
            file=sys.stderr,
        )
        return 130


if __name__ == "__main__":
    sys.exit(main())
