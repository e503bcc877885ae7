"""Fuzzed error paths: any nested configuration a user can type into `make` or the CLI either
works or raises an `AdvgameError` that says what is wrong — never another exception."""

from __future__ import annotations

import math
import os
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import advgame
from advgame.cli import main
from advgame.errors import AdvgameError

KINDS = ["observation", "action", "reward", "cost", "dynamics", "force", "workspace", "bogus"]
FIELDS = [
    "eps", "dims", "mode", "alpha", "schedule", "norm", "space", "targets", "bounded", "timing",
    "std", "params", "body", "name", "every", "probability", "window", "start", "stop", "phase",
    "hold", "persist", "once_per_episode", "param", "low", "high", "scale", "signal", "keys",
    "bogus",
]  # fmt: skip
SCALARS = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-5, 20),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from(["big", "", "linf", "l2", "raw", "normalized", "both", "eval", "torso"]),
)
VALUES = st.recursive(
    SCALARS,
    lambda inner: st.one_of(
        st.lists(inner, max_size=3), st.dictionaries(st.sampled_from(FIELDS), inner, max_size=3)
    ),
    max_leaves=6,
)
DISRUPTORS = st.one_of(
    VALUES,
    st.dictionaries(
        st.sampled_from(KINDS),
        st.one_of(
            st.dictionaries(st.sampled_from(FIELDS), VALUES, max_size=4),
            st.lists(st.dictionaries(st.sampled_from(FIELDS), VALUES, max_size=3), max_size=2),
            VALUES,
        ),
        max_size=3,
    ),
)
MAKE_KWARGS = st.dictionaries(
    st.sampled_from(["preset", "phase", "cost_weight", "max_episode_steps", "bogus"]),
    SCALARS,
    max_size=3,
)


def _make(**kwargs: Any) -> None:
    try:
        game = advgame.make("Hopper-v5", **kwargs)
    except AdvgameError as exc:
        assert str(exc), "an AdvgameError must say what is wrong"
        return
    try:  # what was accepted must also play
        game.reset(seed=0)
        for _ in range(3):
            if not game.agents:
                break
            game.step({a: game.action_space(a).sample() for a in game.agents})
    except AdvgameError:
        pass
    finally:
        game.close()


@settings(
    max_examples=int(os.environ.get("FUZZ_EXAMPLES", 150)),
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
)
@given(DISRUPTORS)
def test_any_nested_disruptor_configuration_is_accepted_or_a_clear_error(config: Any) -> None:
    _make(disruptors=config)


@settings(
    max_examples=int(os.environ.get("FUZZ_EXAMPLES", 80)),
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
)
@given(MAKE_KWARGS)
def test_any_make_keywords_are_accepted_or_a_clear_error(kwargs: dict[str, Any]) -> None:
    _make(**kwargs)


@pytest.mark.parametrize(
    ("kwargs", "words"),
    [
        ({"disruptors": {"observation": {"eps": "big"}}}, "eps"),
        ({"disruptors": {"observation": {"eps": 0.1, "schedule": {"window": [5, 2]}}}}, "window"),
        ({"disruptors": {"observation": None}}, "observation"),
        ({"max_episode_steps": -5}, "max_episode_steps"),
        ({"bogus": 1}, "bogus"),
    ],
)
def test_the_cases_of_the_issue_name_what_is_wrong(kwargs: dict[str, Any], words: str) -> None:
    with pytest.raises(AdvgameError, match=words):
        advgame.make("Hopper-v5", **kwargs)


ARGS = st.lists(
    st.one_of(
        st.sampled_from(
            ["--scenario", "Hopper-v5", "Nope-v0", "--seeds", "--episodes", "--workers",
             "--adversaries", "attack:nope", "preset:nope", "population:/nonexistent",
             "--threat", "--budgets", "--checkpoint", "m=/nonexistent.zip:ppo", "x=y:zzz",
             "--callable", "f=math:nope", "f=nomodule:f", "--normalizer", "--preset", "--method",
             "--iterations", "--set", "bogus=1", "eps=", "--out", "0", "-1", "nan", "abc"]
        ),
        st.text(alphabet="abc:=,-01./", max_size=8),
    ),
    max_size=6,
)  # fmt: skip


@settings(
    max_examples=int(os.environ.get("FUZZ_EXAMPLES", 120)),
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
)
@given(command=st.sampled_from(["evaluate", "report", "resume", "list", "train"]), args=ARGS)
def test_any_command_line_is_accepted_or_a_clear_error(
    command: str, args: list[str], tmp_path_factory: pytest.TempPathFactory
) -> None:
    if command == "train":  # never train for real here: invalid by construction or tiny
        args = [*args, "--iterations", "-1"]
    cwd = tmp_path_factory.mktemp("cli")
    import os

    before = os.getcwd()
    os.chdir(cwd)
    try:
        code = main([command, *args])
    except SystemExit as exc:  # argparse usage errors: exit 2 with a usage line
        code = exc.code if isinstance(exc.code, int) else 2
    finally:
        os.chdir(before)
    assert code in (0, 1, 2)
    assert not math.isnan(float(code))


TRAIN_FIELDS = [
    "scenario", "preset", "learned", "protagonist_algo", "adversary_algo", "protagonist_hparams",
    "iterations", "protagonist_steps", "adversary_steps", "sampling", "train_budget_scale",
    "n_envs", "vec_env", "seed", "disruptors", "task_options", "adversaries", "bogus",
]  # fmt: skip


@settings(max_examples=int(os.environ.get("FUZZ_EXAMPLES", 150)), deadline=None)
@given(st.dictionaries(st.sampled_from(TRAIN_FIELDS), VALUES, max_size=4))
def test_any_train_config_dict_is_accepted_or_a_clear_error(data: dict[str, Any]) -> None:
    """What a config.json or --set can hold: `from_dict` builds it or names what is wrong."""
    from advgame.core.config import from_dict
    from advgame.training import TrainConfig

    try:
        from_dict(TrainConfig, data)
    except AdvgameError as exc:
        assert str(exc)


JOB_FIELDS = ["make_kwargs", "protagonist", "adversary", "adversary_specs", "seeds", "episodes",
              "tags"]  # fmt: skip


@settings(max_examples=int(os.environ.get("FUZZ_EXAMPLES", 150)), deadline=None)
@given(st.dictionaries(st.sampled_from(JOB_FIELDS), VALUES, max_size=4))
def test_any_eval_job_is_accepted_or_a_clear_error(data: dict[str, Any]) -> None:
    from advgame.evaluation import EvalJob

    fields = {"scenario": "Hopper-v5", "protagonist": "p", "protagonist_spec": abs, **data}
    try:
        EvalJob(**fields)
    except AdvgameError as exc:
        assert str(exc)
