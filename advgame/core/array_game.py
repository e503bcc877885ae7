"""The array game: N copies of one scenario stepped as arrays ``[N, ...]``.

`ArrayGame` holds N alike games (one scenario, one disruptor set-up) and plays the
Disrupted-MDP's moves for all of them at once, with the same protocol as `Game` (see
`advgame.core.game`): per step, a *sense* call (observation adversaries see the true state
``s_t`` and choose δ; the protagonists are shown ``s_t + δ``) and an *act* call (environment
adversaries set the simulator, action adversaries perturb the protagonists' actions, the
simulator steps, reward and cost adversaries perturb what the learners observe). Actions go in
as ``{agent: [N, ...]}``; observations, rewards, costs, payoffs, terminations, truncations,
clip counts and info terms come out as arrays. On the hot path there is no Python loop over
copies or agents' dicts:

* each disruptor's budget decode and hook run once over the rows it acts on (one runtime per
  disruptor; `advgame.core.array_hooks.ArrayHooks`), each copy keeping its own clip count;
* schedules are boolean arrays ``[N]`` (constant ones never change; step-dependent ones are
  computed from the copies' step counters, probabilistic ones draw from each copy's own
  generator in the single game's order);
* the simulators step as one batch through the task base's `TaskBase.step_arrays` (MuJoCo v5
  and Safety tasks: `mj_step` of every copy on the simulator threads, observations and rewards
  over ``[N, ...]``). Task bases that cannot batch (Box2D, robosuite, robotics) step copy by
  copy there, and the array game logs that it does.

What stays per copy is what is per copy: resets (each copy's `Game.reset`, so seeds, the
restored model and the first step's schedule draws are the single game's), environment
disruptors (dynamics and forces edit each copy's own model and data, through the copy's own
`Game._disrupt_environment`), and the copies' generators. Every copy plays bit for bit as the
single game with the same seed and the same actions (``tests/test_array_game.py``).

The copies' `Game` objects hold each copy's task and model; while an `ArrayGame` plays them,
their own move state (``t``, observations, movers) is not kept up to date. This module builds the
array state and keeps it in step with the copies (`ArrayGame.reset`, `pull`, `push`); the moves
themselves are `advgame.core.array_moving.ArrayMoves`, which `ArrayGame` inherits (as `Game`
inherits `advgame.core.moving.Moves`).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import Any

import numpy as np
from gymnasium import spaces

from advgame.core.array_moving import ArrayMoves, ArrayStep
from advgame.core.game import Game
from advgame.core.lockstep import alike
from advgame.core.task import GymTask
from advgame.errors import ConfigError

__all__ = ["ArrayGame", "ArrayStep", "unsupported"]

log = logging.getLogger(__name__)
_LOGGED: set[type] = set()


def unsupported(games: Sequence[Game]) -> str | None:
    """Why `games` cannot be one `ArrayGame` (None: they can)."""
    g0 = games[0]
    if not alike(games):
        return "the games are not alike (different scenarios, set-ups or spaces)"
    if not isinstance(g0.task, GymTask):
        return f"{type(g0.task).__name__} is not a single-protagonist Gymnasium task"
    space = g0.observation_space(g0.protagonists[0])
    if not isinstance(space, spaces.Box) or len(space.shape) != 1:
        return f"the protagonist observes {space}, not a flat Box"
    if g0._setup_ds:
        return "workspace (setup-move) disruptors act at reset"
    return None


class ArrayGame(ArrayMoves):
    """N alike games played as arrays (see the module docstring).

    Args:
        games: the copies, built alike (e.g. ``[advgame.make(id, preset=p) for _ in range(N)]``).
        threads: simulator threads of a batched step (``None``: the process's default).

    Raises:
        ConfigError: the games cannot be played as arrays (`unsupported` says why).

    Example:
        >>> import advgame, numpy as np
        >>> game = ArrayGame([advgame.make("Hopper-v5", preset="default") for _ in range(4)])
        >>> obs = game.reset(seed=0)["protagonist"]
        >>> shown = game.sense({"observation_adversary": np.zeros((4, 11))})
        >>> step = game.act({"protagonist": np.zeros((4, 3)), "action_adversary": np.ones((4, 3))})
        >>> step.reward.shape, step.clipped["action_adversary"].tolist()
        ((4,), [0, 0, 0, 0])

    """

    def __init__(self, games: Sequence[Game], threads: int | None = None) -> None:
        reason = unsupported(games)
        if reason is not None:
            raise ConfigError(f"These games cannot be played as one ArrayGame: {reason}.")
        self.games = list(games)
        self.n = len(games)
        self.threads = threads
        g0 = self.games[0]
        self.protagonists = g0.protagonists
        self.adversaries = g0.adversaries
        self.disruptors = g0.disruptors
        """The array runtimes: the first copy's (the copies share their specs and budgets)."""
        self.cost_weight = g0.cost_weight
        self._tasks = [g.task for g in self.games]
        self._task_type = type(g0.task)
        self._limit = g0.task.max_episode_steps
        self._sensing, self._stale = g0._sensing, g0._stale
        self._action_ds, self._reward_ds = g0._action_ds, g0._reward_ds
        self._env_ds, self._act_ds = g0._env_ds, g0._act_ds
        self._p_spaces = g0._p_spaces
        self._rngs = [g._rng for g in self.games]
        n = self.n
        self.t = np.zeros(n, np.int64)
        """Each copy's protagonist step within its episode."""
        self.done = np.ones(n, np.bool_)
        """Copies whose episode is over (reset them before the next act)."""
        self.clip_count = {a: np.zeros(n, np.int64) for a in self.adversaries}
        """Per adversary, each copy's clipped components since its reset."""
        self._last = {a: np.zeros((n, *d.shape)) for a, d in self.disruptors.items()}
        self._has_last = {a: np.zeros(n, np.bool_) for a in self.adversaries}
        self._active = {a: np.zeros(n, np.bool_) for a in self.adversaries}
        self._true: dict[str, np.ndarray] = {}
        self._shown: dict[str, np.ndarray] = {}
        self.last_clipped: dict[str, np.ndarray] = {}
        """Sensing adversaries -> components clipped in the last sense move ``[N]``."""
        if not self._task_type.batched and self._task_type not in _LOGGED:
            _LOGGED.add(self._task_type)
            log.warning(
                "%s cannot batch its simulators: the array game steps its %d copies one by one "
                "(the disruptors still act as arrays).",
                self._task_type.__name__,
                n,
            )

    # -- the phase and budgets ------------------------------------------------------------------
    @property
    def phase(self) -> str:
        """``"train"`` or ``"eval"``: which schedules are live (all copies share it)."""
        return self.games[0].phase

    @phase.setter
    def phase(self, value: str) -> None:
        for g in self.games:
            g.phase = value

    def set_observation_scale(self, target: str, std: Any) -> int:
        """`Game.set_observation_scale` for every copy (normalized-space budgets)."""
        counts = [g.set_observation_scale(target, std) for g in self.games]
        return counts[0]

    # -- episodes -------------------------------------------------------------------------------
    def reset(
        self, seed: int | Sequence[int | None] | None = None, rows: Any = None
    ) -> dict[str, np.ndarray]:
        """Reset copies `rows` (default all): copy ``i`` with ``seed + i``, or ``seed[i]``.

        Each copy resets through its own `Game.reset` (nominal model restored, disruptors reset,
        its generator seeded, the first step's schedules drawn). Returns what every copy's
        protagonists are shown now ``{protagonist: [N, ...]}`` (sense moves still to come).
        """
        idx = np.arange(self.n) if rows is None else np.flatnonzero(np.asarray(rows, np.bool_))
        if seed is None or isinstance(seed, int | np.integer):
            seeds = [None if seed is None else int(seed) + int(i) for i in idx]
        else:
            seeds = [list(seed)[i] for i in idx]
        for i, s in zip(idx, seeds, strict=True):
            self.games[i].reset(seed=s)
            self.pull(int(i))
        return self.shown()

    def pull(self, i: int) -> None:
        """Read copy `i`'s state from its `Game` (after the game moved or reset on its own).

        The single-agent views reset their games themselves (`SingleAgentView.reset` plays the
        moves before the learner's first decision); the array game then goes on from there.
        """
        g = self.games[i]
        if not g._true_obs:  # never reset: nothing to read (the copy stays `done`)
            return
        self._rngs[i] = g._rng
        for p in self.protagonists:
            if p not in self._true:
                space = g.observation_space(p)
                assert isinstance(space, spaces.Box)  # `unsupported` checked it
                self._true[p] = np.zeros((self.n, *space.shape), space.dtype)
                self._shown[p] = self._true[p].copy()
            self._true[p][i] = g._true_obs[p]
            self._shown[p][i] = g._shown[p]
        for a in self.adversaries:
            self._active[a][i] = g._active.get(a, False)
            self._has_last[a][i] = a in g._last
            if a in g._last:
                self._last[a][i] = g._last[a]
            self.clip_count[a][i] = g.disruptors[a].clip_count
        self.t[i] = g.t
        self.done[i] = not g.agents

    def push(self, i: int, sensed: bool) -> None:
        """Write copy `i`'s state back into its `Game`, so that it can go on playing alone.

        `sensed`: whether this step's sense move was made (the game is then at its act move).
        """
        if not self._true:  # never reset or read: the game holds its own state
            return
        g = self.games[i]
        g._true_obs = {p: self._true[p][i].copy() for p in self.protagonists}
        g._shown = {p: self._shown[p][i].copy() for p in self.protagonists}
        g._state = g.task.state(g._true_obs)
        g._active = {a: bool(v[i]) for a, v in self._active.items()}
        g._last = {a: self._last[a][i].copy() for a in self.adversaries if self._has_last[a][i]}
        for a, d in g.disruptors.items():
            d.clip_count = int(self.clip_count[a][i])
        g.t = int(self.t[i])
        g.task._steps = g.t  # type: ignore[attr-defined]  # a GymTask (`unsupported`)
        g.agents = [] if self.done[i] else list(g.possible_agents)
        sense, g._act_next = g._movers(g._active)
        if self.done[i]:
            g.next_movers = frozenset()
        elif sense and not sensed:
            g.move, g.next_movers = "sense", sense
        else:
            g.move, g.next_movers = "act", g._act_next

    def state(self) -> np.ndarray:
        """The true state ``s_t`` of every copy ``[N, ...]`` (what adversaries observe)."""
        return self._true[self.protagonists[0]]

    def observe(self, agent: str) -> np.ndarray:
        """What `agent` observes now in every copy: protagonists what they are shown."""
        return self._shown[agent] if agent in self._shown else self.state()

    def sensing(self) -> np.ndarray:
        """Copies in which an observation adversary moves this step (a sense move) ``[N]``."""
        out = np.zeros(self.n, np.bool_)
        for d in self._sensing:
            out |= self._active[d.agent]
        return out

    def active(self, agent: str) -> np.ndarray:
        """Copies in which adversary `agent`'s action counts this step ``[N]`` (a copy)."""
        return self._active[agent].copy()

    def rows_of(self, agent: str, idx: Sequence[int] | np.ndarray, answers: Sequence[Any]) -> Any:
        """`agent`'s actions for a move from the answers of copies `idx` (in increasing order).

        When every copy answered, `answers` as they are; otherwise ``[N, ...]`` float64 with
        each answer in its copy's row and zeros in the others, which the move ignores (the
        agent does not act there).
        """
        if len(idx) == self.n:
            return answers
        shape = self.games[0].action_space(agent).shape or ()
        full = np.zeros((self.n, *shape), np.float64)
        full[np.asarray(idx, np.intp)] = np.asarray(answers, np.float64)
        return full

    def close(self) -> None:
        """Close every copy."""
        for g in self.games:
            g.close()
