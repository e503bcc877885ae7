"""Fuzzing the user-facing configuration: `advgame.make` and the ``advgame`` command line.

Hypothesis builds malformed *nested* configurations — disruptor dicts whose options, schedules,
dynamics params and workspace shifts hold wrong types, None, strings, negative, NaN and
infinite numbers, reversed windows, unknown keys and out-of-range dimensions — and malformed
`make` keyword sets, and the command line gets argument lists mixing real options with bad
values. The property is the same everywhere: the call succeeds or raises an `AdvgameError`
(the CLI: returns 2 with a one-line message, or argparse's usage exit), never another exception.
The nine cases of issue 24 are plain tests at the end.
"""

from __future__ import annotations

import json
import math
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import advgame
from advgame.cli import main
from advgame.errors import AdvgameError, ConfigError, UnknownNameError

SCENARIO = "InvertedPendulum-v5"  # the cheapest MuJoCo task: 4 observations, 1 action
FUZZ = settings(
    max_examples=150,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)

junk = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-3, 3),
    st.sampled_from([math.nan, math.inf, -math.inf, -0.5, 1e9, 0.05]),
    st.text(max_size=4),
    st.lists(st.integers(-2, 6), max_size=3),
    st.dictionaries(st.text(max_size=3), st.integers(), max_size=2),
)
"""Values of the wrong type or range for almost any field."""

number = st.one_of(st.floats(-1.0, 2.0), st.sampled_from([math.nan, math.inf, -1.0, 0.0]))


def rarely(bad: st.SearchStrategy[Any], valid: st.SearchStrategy[Any]) -> st.SearchStrategy[Any]:
    """`valid` seven times in eight, `bad` otherwise (so that later checks are reached too)."""
    return st.integers(0, 7).flatmap(lambda i: bad if i == 0 else valid)


def maybe(valid: st.SearchStrategy[Any]) -> st.SearchStrategy[Any]:
    """A plausible value most of the time, junk otherwise."""
    return rarely(junk, valid)


schedule = st.one_of(
    junk,
    st.fixed_dictionaries(
        {},
        optional={
            "every": maybe(st.integers(0, 5)),
            "probability": maybe(number),
            "start": maybe(st.integers(-2, 6)),
            "stop": maybe(st.one_of(st.none(), st.integers(-2, 6))),
            "once_per_episode": maybe(st.booleans()),
            "phase": maybe(st.sampled_from(["train", "eval", "both", "test"])),
            "hold": maybe(st.booleans()),
            "persist": maybe(st.booleans()),
            "window": st.lists(st.integers(0, 9), min_size=2, max_size=2),
        },
    ),
)

common = {
    "schedule": schedule,
    "name": maybe(st.sampled_from(["adv", "protagonist", ""])),
    "targets": maybe(st.one_of(st.none(), st.just(["protagonist"]), st.just(["nobody"]))),
    "bounded": maybe(st.booleans()),
}


def options(fields: dict[str, st.SearchStrategy[Any]]) -> st.SearchStrategy[Any]:
    """A disruptor's options dict (any subset of its fields and common ones), rarely junk."""
    valid = st.fixed_dictionaries({}, optional={**common, **fields})
    unknown = st.fixed_dictionaries({"unknown_key": junk}, optional=fields)
    return rarely(st.one_of(unknown, junk), valid)


budget = maybe(st.one_of(number, st.lists(number, max_size=5)))
param = st.one_of(
    junk,
    st.fixed_dictionaries(
        {"kind": maybe(st.sampled_from(["mass", "gravity", "friction", "wind", "length", "x"]))},
        optional={
            "low": maybe(number),
            "high": maybe(number),
            "names": maybe(st.sampled_from([["pole"], ["nope"], [], "pole"])),
            "relative": maybe(st.booleans()),
        },
    ),
)
shift = st.one_of(
    junk,
    st.fixed_dictionaries(
        {"name": maybe(st.just("s"))},
        optional={
            "bodies": maybe(st.sampled_from([["pole"], ["nope"], "pole"])),
            "offset": maybe(st.lists(number, max_size=4)),
            "rgba_high": maybe(st.lists(number, max_size=5)),
        },
    ),
)
KIND_OPTIONS = {
    "observation": options(
        {
            "eps": maybe(st.one_of(budget, st.dictionaries(st.text(max_size=3), number))),
            "norm": maybe(st.sampled_from(["linf", "l2", "l1"])),
            "dims": maybe(st.lists(st.integers(-5, 9), max_size=4)),
            "keys": maybe(st.lists(st.text(max_size=3), max_size=2)),
            "space": maybe(st.sampled_from(["raw", "normalized", "x"])),
            "timing": maybe(st.sampled_from(["sense", "stale", "late"])),
        }
    ),
    "action": options(
        {
            "mode": maybe(st.sampled_from(["additive", "probabilistic", "noisy", "x"])),
            "eps": budget,
            "alpha": maybe(number),
        }
    ),
    "reward": options({"eps": maybe(number), "signal": maybe(st.sampled_from(["reward", "x"]))}),
    "cost": options({"eps": maybe(number)}),
    "dynamics": options({"params": maybe(st.lists(param, max_size=2))}),
    "force": options(
        {
            "bodies": maybe(st.sampled_from([["pole"], ["cart"], ["nope"], [], "pole"])),
            "axes": maybe(st.sampled_from(["xyz", "x", "", "xx", "w"])),
            "max_force": budget,
            "max_torque": maybe(number),
        }
    ),
    "workspace": options({"shifts": maybe(st.lists(shift, max_size=2))}),
    "bogus": junk,
}


@st.composite
def disruptor_configs(draw: st.DrawFn) -> Any:
    """A nested disruptor configuration: {kind: options | [options, ...]}, rarely junk."""
    known = st.sampled_from(sorted(set(KIND_OPTIONS) - {"bogus"}))
    kinds = draw(st.lists(rarely(st.just("bogus"), known), min_size=1, max_size=3))
    out: dict[Any, Any] = {}
    for kind in kinds:
        one = KIND_OPTIONS[kind]
        out[kind] = draw(rarely(st.lists(one, max_size=2), one))
    return draw(rarely(junk, st.just(out)))


make_kwargs = st.fixed_dictionaries(
    {},
    optional={
        "preset": st.one_of(st.sampled_from(["default", "atla", "nope", "Default"]), junk),
        "phase": st.one_of(st.sampled_from(["train", "eval", "both"]), junk),
        "cost_weight": st.one_of(number, junk),
        "max_episode_steps": st.one_of(st.integers(-3, 50), junk),
        "render_mode": st.one_of(st.sampled_from(["rgb_array", "human?"]), junk),
        "reset_noise_scale": st.one_of(st.floats(0, 0.5), junk),
        "bogus": junk,
        "max_episode_step": st.integers(1, 5),
    },
)
"""`make`'s own keywords and the task's (Gymnasium's and the environment class's)."""


def play_briefly(game: Any) -> None:
    """Reset a game that was built and play one joint move, as a user would next."""
    try:
        game.reset(seed=0)
        for _ in range(2):  # the sense move and the act move
            if not game.agents:
                break
            game.step({a: game.action_space(a).sample() for a in game.agents})
    finally:
        game.close()


@FUZZ
@given(disruptors=disruptor_configs())
def test_make_raises_only_advgame_errors_on_malformed_disruptor_configs(disruptors: Any) -> None:
    try:
        game = advgame.make(SCENARIO, disruptors=disruptors)
    except AdvgameError as exc:
        assert str(exc), "an AdvgameError must say what was wrong"
        return
    play_briefly(game)


@FUZZ
@given(kwargs=make_kwargs)
def test_make_raises_only_advgame_errors_on_malformed_keywords(kwargs: dict[str, Any]) -> None:
    try:
        game = advgame.make(SCENARIO, **kwargs)
    except AdvgameError as exc:
        assert str(exc), "an AdvgameError must say what was wrong"
        return
    if "reset_noise_scale" in kwargs:  # the simulator's own parameter: its values are its own
        game.close()
        return
    play_briefly(game)


@FUZZ
@given(disruptors=disruptor_configs())
def test_a_config_json_round_trip_gives_the_same_verdict(disruptors: Any) -> None:
    """What a JSON file holds (lists for tuples, no NaN) is judged like the same dict in code."""
    try:
        text = json.dumps(disruptors, allow_nan=False)
    except (TypeError, ValueError):
        return
    verdicts = []
    for cfg in (disruptors, json.loads(text)):
        try:
            advgame.make(SCENARIO, disruptors=cfg).close()
            verdicts.append("ok")
        except AdvgameError as exc:
            verdicts.append(type(exc).__name__)
    assert verdicts[0] == verdicts[1]


@pytest.mark.parametrize(
    ("kwargs", "exc", "fragments"),
    [
        ({"disruptors": {"observation": {"eps": "big"}}}, ConfigError, ("eps", "'big'")),
        (
            {"disruptors": {"observation": {"eps": 0.1, "schedule": {"window": [5, 2]}}}},
            ConfigError,
            ("Schedule", "'window'", "start", "stop"),
        ),
        ({"disruptors": {"observation": None}}, ConfigError, ("'observation'", "None", "dict")),
        ({"max_episode_steps": -5}, ConfigError, ("max_episode_steps", "-5", ">= 1")),
        ({"bogus": 1}, UnknownNameError, ("'bogus'", "max_episode_steps", "render_mode")),
        ({"render_mode": "rgb-array"}, ConfigError, ("render_mode", "'rgb-array'", "rgb_array")),
    ],
    ids=[
        "eps-string",
        "schedule-window",
        "options-none",
        "negative-steps",
        "unknown-keyword",
        "render-mode",
    ],
)
def test_the_make_cases_of_issue_24_are_advgame_errors(
    kwargs: dict[str, Any], exc: type[AdvgameError], fragments: tuple[str, ...]
) -> None:
    with pytest.raises(exc) as info:
        advgame.make("Hopper-v5", **kwargs)
    for fragment in fragments:
        assert fragment in str(info.value), f"{fragment!r} not in {info.value}"


def test_a_typo_in_a_make_keyword_is_named_with_the_nearest_one() -> None:
    with pytest.raises(UnknownNameError, match='Did you mean "max_episode_steps"'):
        advgame.make(SCENARIO, max_episode_step=10)
    with pytest.raises(ConfigError, match=r"Schedule\.every must be an integer"):
        advgame.make(SCENARIO, disruptors={"action": {"schedule": {"every": "often"}}})


# -- the command line ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    """Paths the CLI fuzzer names: missing, empty folders, a non-zip 'model', garbage JSON."""
    root = tmp_path_factory.mktemp("cli-fuzz")
    (root / "empty").mkdir()
    (root / "fake.zip").write_text("not a model\n")
    (root / "bad.json").write_text('{"iterations": ')
    (root / "run").mkdir()
    (root / "run" / "config.json").write_text('{"scenario": 3}\n')
    names = ["missing", "empty", "fake.zip", "bad.json", "run"]
    return {n: str(root / n) for n in names} | {"out": str(root / "out")}


word = st.sampled_from(["", "x", "-1", "0", "nan", "inf", "1e9", "Hopper-v5", "Hoper-v5", "=", ":"])


def cli_args(paths: dict[str, str]) -> st.SearchStrategy[list[str]]:
    """Argument lists of the fail-fast subcommands, each with at least one bad input."""
    path = st.sampled_from(sorted(paths.values()))
    bad_train = st.sampled_from([
        ["--iterations", "0"], ["--scenario", "Hoper-v5"], ["--set", "bogus=1"],
        ["--set", "protagonist_hparams=[1]"], ["--set", "iterations"], ["--preset", "nope"],
        ["--config", paths["bad.json"]], ["--config", paths["missing"]], ["--seed", "x"],
        ["--set", 'protagonist_hparams={"n_stepz": 8}'], ["--train-budget-scale", "nan"],
        ["--set", "learned=3"], ["--n-envs", "-2"], ["--method", "nope"],
    ])  # fmt: skip
    train = st.tuples(
        st.lists(bad_train, min_size=1, max_size=3),
        st.lists(st.tuples(st.sampled_from(["--protagonist-steps", "--seed", "--preset"]), word)),
    ).map(lambda t: ["train", "--run-dir", paths["out"], "--no-progress"]
          + [a for pair in [*t[0], *t[1]] for a in pair])  # fmt: skip
    spec = st.one_of(
        st.builds(lambda n, p, a: f"{n}={p}:{a}", word, path, st.sampled_from(["ppo", "x", ""])),
        word,
    )
    column = st.sampled_from(["preset:nope", "population:" + paths["missing"], "attack:foo",
                              "learned:" + paths["empty"], "bogus", "population:x,last=-1"])  # fmt: skip
    option = st.one_of(
        st.tuples(st.sampled_from(["--checkpoint", "--normalizer", "--team", "--callable"]), spec),
        st.tuples(
            st.sampled_from(
                [
                    "--seeds",
                    "--episodes",
                    "--workers",
                    "--last",
                    "--threat",
                    "--exploitability",
                    "--scenario",
                    "--raw-obs",
                ]
            ),
            word,
        ),
        st.tuples(st.just("--adversaries"), column),
    )
    evaluate = st.tuples(st.lists(path, max_size=2), st.lists(option, max_size=4)).map(
        lambda t: ["evaluate", *t[0], "--out", paths["out"], *[a for o in t[1] for a in o]]
    )
    report = st.tuples(st.just("report"), path).map(list)
    resume = st.tuples(st.just("resume"), path, st.just("--no-progress")).map(list)
    listing = st.one_of(
        st.lists(word, max_size=2).map(lambda ids: ["list", *ids]),
        word.map(lambda f: ["list", "--family", f]),
    )
    psro = st.one_of(
        st.tuples(path).map(lambda p: ["psro", "--run-dir", p[0], "--resume"]),
        st.sampled_from([["--iterations", "-1"], ["--solver", "x"], ["--set", "x=1"],
                         ["--scenario", "Hoper-v5"], ["--eval-seeds", "0"]]).map(
            lambda bad: ["psro", "--run-dir", paths["out"], *bad]),
    )  # fmt: skip
    return st.one_of(train, evaluate, report, resume, listing, psro)


@given(data=st.data())
@settings(max_examples=120, deadline=None, suppress_health_check=list(HealthCheck))
def test_the_cli_exits_with_a_message_never_a_traceback(
    data: st.DataObject, files: dict[str, str], capsys: pytest.CaptureFixture[str]
) -> None:
    argv = data.draw(cli_args(files), label="argv")
    capsys.readouterr()  # what earlier examples printed
    try:
        status = main(argv)
    except SystemExit as exc:  # argparse's usage errors (and --help)
        assert exc.code in (0, 2), argv
        return
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err
    if status != 0:
        assert status == 2 and err.startswith(f"advgame {argv[0]}: error: "), (argv, status, err)
        assert len(err.splitlines()) == 1, err
