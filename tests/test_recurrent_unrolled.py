"""RecurrentPPO's update with each minibatch unrolled in one LSTM call (`agents/recurrent/ppo.py`).

The unrolled minibatch must give sb3-contrib's numbers: the same values and log-probabilities
bit for bit, and the same training up to float rounding (the per-step gradient terms are summed
in another order), on rollouts whose minibatches hold episode starts.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from sb3_contrib import RecurrentPPO
from sb3_contrib.common.recurrent.buffers import RecurrentRolloutBuffer
from stable_baselines3.common.env_util import make_vec_env

from advgame.agents.learners import LEARNERS
from advgame.agents.recurrent.ppo import UnrolledRecurrentPPO, UnrolledRolloutBuffer, unrolled
from advgame.agents.sa.recurrent import SARecurrentPPO

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def _model(cls: type, **kwargs) -> RecurrentPPO:
    env = make_vec_env("Pendulum-v1", n_envs=2, seed=0)  # 200-step episodes: starts inside
    return cls("MlpLstmPolicy", env, n_steps=256, batch_size=128, n_epochs=2, seed=0,
               device="cpu", policy_kwargs={"lstm_hidden_size": 16}, **kwargs)  # fmt: skip


def _batches(buffer: RecurrentRolloutBuffer, cls: type) -> list:
    """The minibatches `buffer` hands out as `cls` would, for one fixed draw of the split."""
    kept = buffer.__class__
    buffer.__class__ = cls
    try:
        np.random.seed(3)  # noqa: NPY002 (sb3-contrib's buffer draws from the global one)
        return list(buffer.get(128))
    finally:
        buffer.__class__ = kept


def test_unrolled_minibatches_give_sb3_contribs_values_and_log_probs() -> None:
    model = _model(UnrolledRecurrentPPO)
    assert type(model.rollout_buffer) is UnrolledRolloutBuffer
    model.learn(512)  # a filled buffer
    plain = _batches(model.rollout_buffer, RecurrentRolloutBuffer)
    fast = _batches(model.rollout_buffer, UnrolledRolloutBuffer)
    assert any(float(b.episode_starts.sum()) > 0 for b in plain)  # the loop path is exercised
    assert all(float(b.episode_starts.abs().sum()) == 0 for b in fast)  # one call each
    with torch.no_grad():
        for slow, quick in zip(plain, fast, strict=True):
            mask = slow.mask > 1e-8
            a = model.policy.evaluate_actions(slow.observations, slow.actions,
                                              slow.lstm_states, slow.episode_starts)  # fmt: skip
            b = model.policy.evaluate_actions(quick.observations, quick.actions,
                                              quick.lstm_states, quick.episode_starts)  # fmt: skip
            assert torch.equal(a[0].flatten()[mask], b[0].flatten()[mask])  # values
            assert torch.equal(a[1][mask], b[1][mask])  # log-probabilities


def test_training_matches_sb3_contrib_up_to_rounding() -> None:
    stock = _model(RecurrentPPO)  # each built and trained in turn: they share NumPy's global
    start = [p.detach().clone() for p in stock.policy.parameters()]  # generator (the splits)
    stock.learn(1024)
    fast = _model(UnrolledRecurrentPPO)
    fast.learn(1024)
    for p, q in zip(stock.policy.parameters(), fast.policy.parameters(), strict=True):
        torch.testing.assert_close(q, p, atol=1e-6, rtol=1e-5)
    assert any(not torch.equal(q, s) for q, s in zip(fast.policy.parameters(), start, strict=True))


def test_a_reset_inside_a_sequence_keeps_the_step_by_step_path() -> None:
    states = (torch.ones(1, 2, 3), torch.ones(1, 2, 3))
    starts = torch.tensor([1.0, 0.0, 0.0, 0.0, 0.0, 0.0])  # 2 sequences of 3: reset at a start
    (h, c), marks = unrolled(states, starts)
    assert h[0, 0].sum() == 0 and h[0, 1].sum() == 3 and c[0, 0].sum() == 0
    assert not marks.any()
    inside = torch.tensor([0.0, 1.0, 0.0, 0.0, 0.0, 0.0])  # a reset after a first step
    same, kept = unrolled(states, inside)
    assert same is states and kept is inside


def test_the_recurrent_learners_train_unrolled_and_load_sb3_contrib_files(tmp_path: Path) -> None:
    assert LEARNERS["recurrent-ppo"].model_class() is UnrolledRecurrentPPO
    assert issubclass(SARecurrentPPO, UnrolledRecurrentPPO)
    outside = _model(RecurrentPPO)
    outside.save(tmp_path / "outside.zip")
    back = UnrolledRecurrentPPO.load(tmp_path / "outside.zip", device="cpu")
    assert type(back.rollout_buffer) is UnrolledRolloutBuffer
    obs = np.zeros((1, 3), dtype=np.float32)
    assert np.array_equal(back.predict(obs, deterministic=True)[0],
                          outside.predict(obs, deterministic=True)[0])  # fmt: skip
