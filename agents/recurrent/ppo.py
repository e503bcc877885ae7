"""sb3-contrib's ``RecurrentPPO`` with each minibatch's sequences unrolled in one LSTM call.

sb3-contrib cuts a rollout into sequences that begin at an episode start or at the boundary
between two environments' steps, pads them to one length, and marks each row's episode start.
Its ``_process_sequence`` runs the LSTM in one call only when no row of the minibatch starts
an episode; otherwise it loops in Python over the padded length, one LSTM call per step,
zeroing the memory of the sequences that start there. A minibatch of a PPO update nearly
always holds an episode start, so an update paid that loop on every minibatch.

A reset can only fall on a sequence's first step (the cut guarantees it), so zeroing those
sequences' initial states up front and clearing the marks gives the same unroll with no reset
inside: `unrolled` does it, `UnrolledRolloutBuffer` hands out minibatches so prepared, and
`UnrolledRecurrentPPO` trains on them. The values and log-probabilities are the same numbers
(tested bit for bit against sb3-contrib's loop); training is the same up to float rounding
(the per-step gradient terms are summed in another order). At the zoo's setting
(8 envs x 2,048 steps, 1,024-step minibatches, 10 epochs) training ran 1,643 steps/s against
sb3-contrib's 841 (``benchmarks/bench_recurrent.py``, 27 Nov, quiet cores). Checkpoints are
sb3-contrib's: saved and loaded by either class.
"""

from __future__ import annotations

from typing import Any

import torch
from sb3_contrib import RecurrentPPO
from sb3_contrib.common.recurrent.buffers import RecurrentRolloutBuffer
from sb3_contrib.common.recurrent.type_aliases import RNNStates

__all__ = ["UnrolledRecurrentPPO", "UnrolledRolloutBuffer", "unrolled"]

States = tuple[torch.Tensor, torch.Tensor]


def unrolled(states: States, starts: torch.Tensor) -> tuple[States, torch.Tensor]:
    """The same unroll with its resets applied up front: ``(states, starts)`` for one LSTM call.

    Args:
        states: an LSTM's ``(h, c)`` at each sequence's first step, ``[layers, n_seq, hidden]``.
        starts: the episode-start mark of each row of the padded, flattened minibatch
            (``[n_seq * max_len]``, sequence-major, as sb3-contrib lays it out).

    Returns:
        The states with the sequences that start an episode zeroed, and all-zero marks. Where a
        mark falls after a sequence's first step (sb3-contrib's buffer never makes one) the
        input is returned unchanged, for the step-by-step path.

    """
    grid = starts.reshape(states[0].shape[1], -1)
    if torch.any(grid[:, 1:] != 0):
        return states, starts
    keep = (1.0 - grid[:, 0]).view(1, -1, 1)
    return (states[0] * keep, states[1] * keep), torch.zeros_like(starts)


class UnrolledRolloutBuffer(RecurrentRolloutBuffer):
    """sb3-contrib's recurrent rollout buffer whose minibatches need no reset inside (`unrolled`)."""

    def _get_samples(self, *args: Any, **kwargs: Any) -> Any:
        """sb3-contrib's minibatch with both LSTMs' resets applied to their initial states."""
        batch = super()._get_samples(*args, **kwargs)
        (h_pi, c_pi), (h_vf, c_vf) = batch.lstm_states
        pi, starts = unrolled((h_pi, c_pi), batch.episode_starts)
        vf, _ = unrolled((h_vf, c_vf), batch.episode_starts)
        return batch._replace(lstm_states=RNNStates(pi, vf), episode_starts=starts)


class UnrolledRecurrentPPO(RecurrentPPO):
    """``RecurrentPPO`` training on `UnrolledRolloutBuffer` minibatches (the same update, faster).

    Takes ``RecurrentPPO``'s arguments; the model, its saved files and its play are
    sb3-contrib's. Dict observations keep sb3-contrib's own buffer (advgame's recurrent
    learners take flat observations only).
    """

    def _setup_model(self) -> None:
        super()._setup_model()
        if type(self.rollout_buffer) is RecurrentRolloutBuffer:
            # the subclass adds no state: only how minibatches are handed out
            self.rollout_buffer.__class__ = UnrolledRolloutBuffer
