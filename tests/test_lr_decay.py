"""A decaying learning rate follows the run's steps however the run is cut into ``learn`` calls.

The alternation loop trains each side in one ``learn`` call per phase and a best response in
chunks; SB3's schedule input restarts its range at every call, so `LinearDecay` maps it back to
the run's step count. Checked at every PPO update of a real `Side`, against the formula.
"""

from __future__ import annotations

import pytest

from advgame.agents import PPOConfig
from advgame.agents.common.side import Side
from advgame.core.views import view_factory

pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.mark.parametrize("calls", [(256,), (64, 64, 128), (128, 64, 64)])
def test_the_rate_at_every_update_is_the_run_long_line(calls: tuple[int, ...]) -> None:
    total, lr = sum(calls), 1e-3
    fns = [view_factory("InvertedPendulum-v5", "protagonist", {})]
    side = Side("protagonist", PPOConfig(n_steps=32, batch_size=32, n_epochs=1,
                                         learning_rate=lr), fns, 0, total)  # fmt: skip
    seen: list[tuple[int, float]] = []
    train = side.model.train

    def spying_train() -> None:
        model = side.model
        seen.append((model.num_timesteps, model.lr_schedule(model._current_progress_remaining)))
        train()

    side.model.train = spying_train
    try:
        for steps in calls:
            side.learn(steps)
    finally:
        side.close()
    assert [t for t, _ in seen] == list(range(32, total + 1, 32))
    for t, rate in seen:
        assert rate == pytest.approx(lr * (1 - t / total), rel=1e-9, abs=1e-15), (t, seen)
