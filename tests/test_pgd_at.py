"""Adversarial training on the current policy: the attack in the learner's views reads the live
learner (its current weights and normalizer), and collection never changes those weights."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch

from advgame.adversaries import MADAttack
from advgame.agents import PPOConfig
from advgame.agents.common.side import Side
from advgame.cli import main
from advgame.core.views import view_factory


def test_the_attack_reads_the_live_learner_and_collection_leaves_it_unchanged(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    torch.set_num_threads(1)
    seen: list[Any] = []
    rows: list[int] = []
    scorer = MADAttack.numpy_scorer  # what each walk of the attack scores its iterates with

    def spy(self: MADAttack, victim: Any, clean: Any) -> Any:
        seen.append(victim.model)
        rows.append(len(clean))
        net = victim.numpy_net("mean")  # the NumPy copy it walks through: the weights as they are
        with torch.no_grad():
            live = victim.action_mean(torch.as_tensor(clean)).numpy()
        np.testing.assert_allclose(net.forward(clean)[0], live, rtol=1e-5, atol=1e-6)
        return scorer(self, victim, clean)

    monkeypatch.setattr(MADAttack, "numpy_scorer", spy)
    fns = [view_factory("Hopper-v5", "protagonist", {"observation_adversary": MADAttack(steps=2)},
                        preset="atla") for _ in range(2)]  # fmt: skip
    side = Side("protagonist", PPOConfig(n_steps=64, batch_size=32, n_epochs=1), fns, 0, 256)
    before = [p.detach().clone() for p in side.model.policy.parameters()]
    at_update: list[list[torch.Tensor]] = []
    train = side.model.train

    def checked_train() -> None:  # what collection left: the weights the attack read
        at_update.append([p.detach().clone() for p in side.model.policy.parameters()])
        train()

    side.model.train = checked_train
    side.learn(64 * 2)
    assert seen and all(m is side.model for m in seen)  # the current policy, not a copy
    # the two views bound to one learner are attacked in one walk (alone only where their
    # episodes are out of step, e.g. one just reset)
    assert rows.count(2) > rows.count(1)
    assert all(torch.equal(a, b) for a, b in zip(before, at_update[0], strict=True))
    after = [p.detach() for p in side.model.policy.parameters()]
    assert any(not torch.equal(a, b) for a, b in zip(before, after, strict=True))  # PPO updated
    seen.clear()
    side.learn(64 * 2)  # the next rollout attacks the updated policy: still the live model
    assert seen and all(m is side.model for m in seen)
    side.close()


def test_pgd_at_trains_resumes_and_its_attack_moves_the_learner(
    tmp_path: Path, tiny_atla: Callable[..., list[str]]
) -> None:
    args = tiny_atla(1)
    args[args.index("atla")] = "pgd-at"
    run = tmp_path / "pgd"
    assert main(["train", *args, "--run-dir", str(run)]) == 0
    cfg = json.loads((run / "config.json").read_text())
    assert cfg["adversaries"] == {"observation_adversary": "mad"} and cfg["learned"] == []
    cfg["iterations"] = 2
    (run / "config.json").write_text(json.dumps(cfg))
    assert main(["resume", str(run), "--no-progress"]) == 0
    rows = (run / "progress.csv").read_text().splitlines()
    assert len(rows) == 3 and np.isfinite(float(rows[-1].split(",")[3]))
