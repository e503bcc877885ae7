"""``Q^π`` of a frozen policy, learned by robust Sarsa: the critic behind `RobustSarsaAttack`.

`collect` plays the policy (its deterministic actions) in the scenario's nominal game and keeps
``(s, μ(s), r, s', μ(s'), done)`` with ``μ`` the policy's mean action *before* the action
space's clip, which is what the attack differentiates (a recurrent policy's with its memory
of the episode at each step). `fit_sarsa` fits a small network to the
Sarsa target with the action-robustness term of Zhang et al. 2020 (see
`adversaries.robust_sarsa`).
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces

from advgame.core.config import write_atomic
from advgame.core.numpy_net import NetCache, NumpyNet
from advgame.errors import ConfigError

__all__ = ["QNetwork", "collect", "fit_sarsa", "probe_observations"]

log = logging.getLogger(__name__)


def probe_observations(size: int, n: int = 64) -> Any:
    """Fixed pseudo-random observations ``[n, size]`` (seed 0), for fingerprinting a policy."""
    import torch

    rng = np.random.default_rng(0)
    return torch.as_tensor(rng.uniform(-2.0, 2.0, (n, size)), dtype=torch.float32)


class QNetwork:
    """``Q(s, a)``: an MLP on standardized ``[s, a]``, in units of the rewards' scale."""

    def __init__(self, obs_dim: int, act_dim: int, hidden: tuple[int, ...], stats: dict) -> None:
        import torch
        from torch import nn

        layers: list[Any] = []
        width = obs_dim + act_dim
        for h in hidden:
            layers += [nn.Linear(width, h), nn.Tanh()]
            width = h
        self.net = nn.Sequential(*layers, nn.Linear(width, 1))
        self.hidden = tuple(hidden)
        self.stats = {k: np.asarray(v, dtype=np.float32) for k, v in stats.items()}
        self._t = {k: torch.as_tensor(v) for k, v in self.stats.items()}
        self._numpy = NetCache()

    def __call__(self, obs: Any, action: Any) -> Any:
        """``Q`` of raw observations ``[n, obs]`` and actions ``[n, act]`` (``[n]``)."""
        import torch

        t = self._t
        x = torch.cat(
            [(obs - t["obs_mean"]) / t["obs_std"], (action - t["act_mean"]) / t["act_std"]], -1
        )
        return self.net(x).squeeze(-1)

    def numpy_net(self) -> NumpyNet | None:
        """The network (after the standardization of ``[s, a]``) as a `NumpyNet`, or None."""
        return self._numpy.get("q", [self.net], None)

    def save(self, path: Path) -> None:
        """Write the network and its statistics to `path` (atomically)."""
        import io

        import torch

        buf = io.BytesIO()
        torch.save(
            {"hidden": self.hidden, "stats": self.stats, "state": self.net.state_dict()}, buf
        )
        path.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(path, buf.getvalue())

    @classmethod
    def load(cls, path: Path) -> QNetwork:
        """Read a network written by `save`; a damaged file says so."""
        import torch

        try:
            data = torch.load(path, weights_only=False)
            stats, hidden = data["stats"], tuple(data["hidden"])
            q = cls(stats["obs_mean"].size, stats["act_mean"].size, hidden, stats)
            q.net.load_state_dict(data["state"])
        except Exception as exc:  # a truncated or foreign file: learn it again
            raise ConfigError(
                f"The Robust Sarsa critic {path} cannot be read ({type(exc).__name__}: {exc}); "
                "delete it and it is learned again."
            ) from None
        q.net.eval()
        return q


def collect(
    scenario: str, agent: str, victim: Any, samples: int, seed: int
) -> dict[str, np.ndarray]:
    """Play `victim` as `agent` in `scenario`'s nominal game for `samples` act moves.

    Each transition keeps ``μ(s)`` and ``μ(s')`` as the victim takes them then: a recurrent
    victim is reset at every episode start and asked with the memory it carries at that
    step (``μ(s')`` with the memory after acting on ``s``), so its ``Q^π`` is learned on the
    actions it really plays.
    """
    from advgame.core.registry import make

    game = make(scenario, disruptors={})
    space = game.action_space(agent)
    if not isinstance(space, spaces.Box):
        raise ConfigError(
            f"Robust Sarsa learns Q of continuous actions; {agent!r} acts in {space}."
        )
    rows: dict[str, list[Any]] = {k: [] for k in ("obs", "act", "rew", "cost", "done", "next")}
    next_act: list[np.ndarray] = []
    episode, pending = 0, False  # pending: the last row's μ(s') is the next row's μ(s)
    try:
        game.reset(seed=seed)
        victim.reset(None)  # unseeded: a sampling victim's torch generator stays as it was
        obs = np.asarray(game.observe(agent), dtype=np.float32)
        while len(rows["obs"]) < samples:
            mean = _mean(victim, obs)
            if pending:
                next_act.append(mean)
            move = game.play({agent: victim.act(obs)})
            row = (obs, mean, move.reward, move.cost, move.terminated)
            for key, value in zip(("obs", "act", "rew", "cost", "done"), row, strict=True):
                rows[key].append(value)
            obs = np.asarray(game.observe(agent), dtype=np.float32)
            rows["next"].append(obs)
            pending = not (move.terminated or move.truncated)
            if not pending:  # the successor's action with this episode's memory, then a new one
                next_act.append(_mean(victim, obs))
                episode += 1
                game.reset(seed=seed + episode)
                victim.reset(None)
                obs = np.asarray(game.observe(agent), dtype=np.float32)
        if pending:
            next_act.append(_mean(victim, obs))
    finally:
        game.close()
    return {
        "obs": np.asarray(rows["obs"]),
        "act": np.asarray(rows["act"], dtype=np.float32),
        "rew": np.asarray(rows["rew"], dtype=np.float32),
        "cost": np.asarray(rows["cost"], dtype=np.float32),
        "done": np.asarray(rows["done"], dtype=np.float32),
        "next": np.asarray(rows["next"]),
        "next_act": np.asarray(next_act, dtype=np.float32),
        "act_range": np.asarray((space.high - space.low) / 2, dtype=np.float32),
    }


def _mean(victim: Any, obs: np.ndarray) -> np.ndarray:
    """The victim's mean action at one observation (with the memory it carries now)."""
    import torch

    with torch.no_grad():
        return victim.action_mean(torch.as_tensor(obs[None])).numpy()[0]


def fit_sarsa(
    scenario: str,
    agent: str,
    victim: Any,
    *,
    samples: int,
    epochs: int,
    batch_size: int,
    hidden: tuple[int, ...],
    gamma: float,
    lr: float,
    reg: float,
    reg_eps: float,
    reg_steps: int,
    seed: int,
    signal: str = "reward",
) -> QNetwork:
    """Learn ``Q^π`` of `victim` on `scenario` by robust Sarsa; return the network.

    `signal` is what ``Q`` sums: ``"reward"`` (the protagonist's reward) or ``"cost"`` (the true
    cost of a safe scenario: ``Q_c^π``).
    """
    import torch

    torch.manual_seed(seed)
    data = collect(scenario, agent, victim, samples, seed)
    next_act = data.pop("next_act")  # the successor's action, as the policy takes it
    act_range = data.pop("act_range")
    cost = data.pop("cost")
    if signal == "cost":  # Q_c^π: the same Sarsa fit on the true cost
        data["rew"] = cost
    stats = _stats(data)
    q = QNetwork(data["obs"].shape[1], data["act"].shape[1], hidden, stats)
    target = QNetwork(data["obs"].shape[1], data["act"].shape[1], hidden, stats)
    opt = torch.optim.Adam(q.net.parameters(), lr=lr, foreach=True)
    t = {k: torch.as_tensor(v) for k, v in data.items()} | {"next_act": torch.as_tensor(next_act)}
    reward = t["rew"] / float(stats["rew_scale"])
    # The last step of a truncated episode bootstraps on its own next state; a terminal one not.
    alive = 1.0 - t["done"]
    radius = torch.as_tensor(reg_eps * act_range)
    n = len(reward)
    gen = torch.Generator().manual_seed(seed)
    for _epoch in range(epochs):
        target.net.load_state_dict(q.net.state_dict())
        for idx in torch.randperm(n, generator=gen).split(batch_size):
            s, a = t["obs"][idx], t["act"][idx]
            with torch.no_grad():
                y = reward[idx] + gamma * alive[idx] * target(t["next"][idx], t["next_act"][idx])
            value = q(s, a)
            loss = ((y - value) ** 2).mean()
            if reg > 0:
                loss = loss + reg * _action_roughness(q, s, a, value, radius, reg_steps)
            opt.zero_grad()
            loss.backward()
            opt.step()
    log.info("Robust Sarsa fitted on %d transitions (last TD loss %.4g)", n, float(loss.detach()))
    q.net.eval()
    return q


def _action_roughness(q: QNetwork, s: Any, a: Any, value: Any, radius: Any, steps: int) -> Any:
    """``mean max_{â ∈ B(a)} (Q(s, â) − Q(s, a))²`` with the max by signed-gradient steps."""
    import torch

    delta = (torch.rand_like(a) * 2 - 1) * radius
    for _ in range(steps):
        delta.requires_grad_(True)
        gap = ((q(s, a + delta) - value.detach()) ** 2).sum()
        (grad,) = torch.autograd.grad(gap, delta)
        delta = torch.maximum(
            torch.minimum(delta + 0.5 * radius * grad.sign(), radius), -radius
        ).detach()
    return ((q(s, a + delta) - value) ** 2).mean()


def _stats(data: dict[str, np.ndarray]) -> dict[str, Any]:
    """Standardization of the network's inputs and the reward scale, from the samples."""
    act = data["act"]
    return {
        "obs_mean": data["obs"].mean(0),
        "obs_std": data["obs"].std(0) + 1e-6,
        "act_mean": act.mean(0),
        "act_std": act.std(0) + 1e-6,
        "rew_scale": np.float32(max(float(np.abs(data["rew"]).mean()), 1e-6)),
    }
