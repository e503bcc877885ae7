"""The ``advgame campaign`` and ``advgame zoo`` commands (see `advgame.workflows.campaign`, `advgame.workflows.zoo`)."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path
from typing import Any

from advgame.errors import ConfigError

__all__ = ["campaign_parser", "zoo_parser"]


def campaign_parser(sub: Any, executor_arguments: Callable[..., None]) -> None:
    """``advgame campaign FILE``: train, evaluate, table (and release) a campaign."""
    p = sub.add_parser(
        "campaign",
        help="train a grid of methods x seeds, evaluate it in one threat model, write the table",
        description="Run a campaign file (TOML, see advgame.workflows.campaign): trains every unfinished "
        "run (interrupted ones resume), evaluates every finished one, writes campaign.md, and "
        "keeps status.json up to date. Run it again to continue.",
    )
    p.add_argument("file", help="the campaign file (e.g. zoo/hopper.toml)")
    p.add_argument("--out", help="its folder (default: beside the file, named after it)")
    p.add_argument("--stage", choices=("all", "train", "evaluate"), default="all",
                   help="only train, only evaluate finished runs, or both (default)")  # fmt: skip
    p.add_argument("--max-runs", type=int, metavar="K", help="train at most K unfinished runs now")
    p.add_argument("--runs", metavar="RUN,...",
                   help="train only these runs (METHOD-sSEED, comma-separated), in this order")  # fmt: skip
    p.add_argument("--status", action="store_true",
                   help="print what is done and the training left, draw the training curves so "
                   "far (progress.png) and stop")  # fmt: skip
    p.add_argument("--park", action="store_true",
                   help="park every run in training at its last checkpoint in parked/ (kept "
                   "beside runs/, not in git: copy it to resume elsewhere), or in "
                   "$ADVGAME_PARK/CAMPAIGN when that is set, and stop")  # fmt: skip
    p.add_argument("--park-every", type=float, metavar="MINUTES",
                   help="while training, park the runs trained here every MINUTES (as --park "
                   "does), so a process killed without --park loses at most that much; default "
                   "30 when $ADVGAME_PARK is set, else never (0: never)")  # fmt: skip
    p.add_argument("--release", metavar="ZOO", nargs="?", const="", default=None,
                   help="after the table, copy each method's median agent into the zoo "
                   "(default: the repository's zoo/) with its manifest entry")  # fmt: skip
    p.add_argument("--no-progress", action="store_true", help="no progress bars or log lines")
    executor_arguments(p, workers=2)
    p.set_defaults(func=_cmd_campaign)


def _cmd_campaign(args: argparse.Namespace) -> int:
    from advgame.workflows.campaign import (
        done_runs,
        evaluation_curves,
        load_campaign,
        park_campaign,
        progress_curves,
        run_campaign,
        search_status,
        seconds_left,
        table_status,
        write_status,
    )

    campaign = load_campaign(args.file)
    out = Path(args.out) if args.out else Path(args.file).with_suffix("")
    if args.max_runs is not None and args.max_runs < 0:
        raise ConfigError(f"--max-runs must be >= 0, got {args.max_runs}.")
    if args.park:
        from advgame.workflows.park import park_root

        parked = park_campaign(campaign, out)
        for run, iteration in parked.items():
            print(f"parked {run} at iteration {iteration} in {park_root(out) / run}")
        print(
            f"parked {len(parked)} run(s)" + (f"; {park_root(out)} is not in git" if parked else "")
        )
        return 0
    if args.status:
        out.mkdir(parents=True, exist_ok=True)
        status = write_status(campaign, out)
        left = seconds_left(campaign, out, status)
        for run, s in status["runs"].items():
            secs = left.get(run)
            eta = f", about {secs / 3600:.1f} h left" if secs is not None else ""
            print(f"{run}: {s['state']} ({s['iteration']}/{s['of']}){eta}")
        known = [v for v in left.values() if v is not None]
        if known:
            unknown = len(left) - len(known)
            print(
                f"training left: about {sum(known) / 3600:.1f} worker-hours for {len(known)} "
                f"run(s), at the rates they (or their method's runs) trained at"
                + (f"; {unknown} run(s) without a measured rate" if unknown else "")
            )
        elif left:
            print(f"training left: {len(left)} run(s), none with a measured rate yet")
        print(f"evaluated: {', '.join(status['evaluated']) or 'none'}; table: {status['table']}")
        search = search_status(campaign, out, done_runs(status))
        if search is not None:
            print(
                f"optimal attack (finished runs): {search['trained']}/{search['candidates']} "
                f"candidates trained, {search['trained_steps']:,}/{search['steps']:,} "
                "adversary steps"
            )
        cells = table_status(campaign, out, done_runs(status))
        print(
            f"table (finished runs, without the optimal column): {cells['played']}/"
            f"{cells['cells']} cells played"
        )
        curves = progress_curves(campaign, out)
        print(
            f"training curves so far: {curves}"
            if curves
            else "training curves: nothing to draw yet"
        )
        evaluated = evaluation_curves(campaign, out)
        if evaluated:
            print(f"in-training evaluation curves so far: {evaluated}")
        return 0
    minutes = _park_minutes(args.park_every)
    if minutes and args.stage != "evaluate":
        from advgame.workflows.park import park_root

        print(f"campaign: parking the runs it trains every {minutes:g} min in {park_root(out)}")
    path = run_campaign(
        campaign, out, workers=args.workers, executor=args.executor, address=args.address,
        stage=args.stage, max_runs=args.max_runs, progress=not args.no_progress,
        only=[r.strip() for r in args.runs.split(",") if r.strip()] if args.runs else None,
        park_every=60 * minutes,
    )  # fmt: skip
    print(f"campaign: {path}")
    if args.release is not None and args.stage != "train":
        from advgame.workflows.zoo import release_campaign

        for e in release_campaign(campaign, out, args.release or None):
            print(
                f"released {e.id}: natural {e.natural_return:.1f}, worst {e.worst_attack_return:.1f}"
            )
    return 0


def zoo_parser(sub: Any) -> None:
    """``advgame zoo list``: the released agents."""
    p = sub.add_parser("zoo", help="the released agents: list the manifest")
    p.add_argument("action", choices=("list",), help="list: print every released agent")
    p.add_argument(
        "--root",
        help="the zoo folder (default: $ADVGAME_ZOO, the advgame-zoo package or the repository's zoo/)",
    )
    p.set_defaults(func=_cmd_zoo)


def _cmd_zoo(args: argparse.Namespace) -> int:
    from advgame.workflows import zoo

    root = Path(args.root) if args.root else zoo.default_root()
    why = zoo.missing(root)
    if why is not None:
        print(why)
        return 0
    found = zoo.entries(root)
    if not found:
        print(f"no released agents in {root}")
        return 0
    wid = max(len("id"), *(len(e.id) for e in found))  # columns as wide as the longest name
    wsc = max(len("scenario"), *(len(e.scenario) for e in found))
    print(f"{'id':<{wid}} {'scenario':<{wsc}} {'steps':>9} {'seed':>4} {'natural':>8} "
          f"{'worst':>8}  worst adversary")  # fmt: skip
    for e in found:
        zoo.verify(e, root)
        print(f"{e.id:<{wid}} {e.scenario:<{wsc}} {e.steps:>9} {e.seed:>4} "
              f"{e.natural_return:>8.1f} {e.worst_attack_return:>8.1f}  "
              f"{e.worst_attack}" + (f" ({e.threat})" if e.threat else ""))  # fmt: skip
    return 0


def _park_minutes(given: float | None) -> float:
    """``--park-every``: as given, else 30 minutes where `PARK_ENV` names a folder, else 0."""
    import os

    from advgame.workflows.park import PARK_ENV

    if given is None:
        return 30.0 if os.environ.get(PARK_ENV, "").strip() else 0.0
    if not given >= 0:
        raise ConfigError(f"--park-every must be >= 0 minutes, got {given}.")
    return given
