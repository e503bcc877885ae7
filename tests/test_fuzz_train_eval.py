"""Fuzzed configs beyond `make`: any `TrainConfig` dict (config.json, --set) and any `EvalJob`
fields are accepted or an `AdvgameError` that says what is wrong, never another exception."""

from __future__ import annotations

import os
from typing import Any

from hypothesis import given, settings
from hypothesis import strategies as st

from advgame.errors import AdvgameError

FIELDS = ["eps", "dims", "mode", "schedule", "every", "window", "kind", "std", "bogus"]
SCALARS = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-5, 20),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from(["big", "", "ppo", "atla", "Hopper-v5", "gauss:0.1", "mad", "uniform"]),
)
VALUES = st.recursive(
    SCALARS,
    lambda inner: st.one_of(
        st.lists(inner, max_size=3), st.dictionaries(st.sampled_from(FIELDS), inner, max_size=3)
    ),
    max_leaves=6,
)


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
