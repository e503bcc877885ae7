"""MaMuJoCo scenarios: a factorized MuJoCo robot whose agents are protagonists of one team.

`MaMuJoCoTask` wraps ``gymnasium_robotics.mamujoco_v1.parallel_env`` (it does not fork it): the
env's agents (``"agent_0"``, ``"agent_1"``, ...) are the protagonists, its global state is what
adversaries observe, and its one shared MuJoCo model is what dynamics and force disruptors edit.
The table of factorizations is `advgame.scenarios.mamujoco_list`.

Presets of every MaMuJoCo scenario (the paper's multi-agent settings, as bounded games):

* ``default``: bounded observation (ε = 0.1) and action (ε = 0.1) adversaries on every agent.
* ``full``: observation, reward and action adversaries on every agent, a per-episode dynamics
  shift (mass, gravity, friction, damping, gear within ±20 % of nominal) and forces on a body.
* ``partial``: observation and action adversaries on the first agent only (a partial attack).
* ``state-gauss-0.1``/``action-gauss-0.1``/``reward-gauss-0.1``: the paper's random mode,
  N(0, 0.1) noise on every agent's state, action or observed reward.
* ``state-gauss-0.1-partial``/``action-gauss-0.1-partial``/``reward-gauss-0.1-partial``: the
  same noise on the first agent only (the paper's partial attacks).
"""

from __future__ import annotations

import dataclasses
import os
import tempfile
from collections.abc import Mapping
from typing import Any

import gymnasium as gym

from advgame.adversaries import GaussianAdversary
from advgame.core.registry import Preset
from advgame.core.task import MujocoSim, StepResult, TaskBase
from advgame.disruptors import (
    ActionDisruptor,
    ForceDisruptor,
    ObservationDisruptor,
    RewardDisruptor,
)
from advgame.errors import AdvgameError, ConfigError, UnknownScenarioError, did_you_mean
from advgame.scenarios.common import gaussian_presets
from advgame.scenarios.mamujoco_list import VARIANTS
from advgame.scenarios.mujoco import FORCES as _GYM_FORCES
from advgame.scenarios.mujoco import dynamics_shift  # the single-agent ±20 % shift, shared

__all__ = ["FIRST_AGENT", "FORCES", "MaMuJoCoTask", "make_task", "presets"]

FIRST_AGENT = "agent_0"
"""MaMuJoCo's first agent id: the target of the partial-attack presets."""

FORCES: dict[str, tuple[tuple[str, ...], str, float]] = {
    **{env_id.removesuffix("-v5"): force for env_id, force in _GYM_FORCES.items()},
    "ManySegmentSwimmer": (("torso",), "xy", 1.0),
    "ManySegmentAnt": (("torso_0",), "xyz", 5.0),
    "CoupledHalfCheetah": (("torso0", "torso1"), "xz", 5.0),
}
"""Force adversary per MaMuJoCo scenario: (bodies, world axes, bound per component in newtons);
the single-agent robots reuse `advgame.scenarios.mujoco.FORCES`."""


class MaMuJoCoTask(TaskBase):
    """A MaMuJoCo ParallelEnv as a task base: one protagonist per agent of the factorization.

    MaMuJoCo gives every agent the same reward (checked on every step: the team reward is taken
    once) and one shared info dict, which is copied so that no two agents share a mutable dict.
    The cost is 0. An episode ends for the whole team when any agent terminates or truncates.

    Two upstream defects are worked around without forking: Pusher's agent_0 observation layout
    varies between instances (`_fix_observation_layout`), and ManySegment models are generated
    into a shared, self-deleting file inside the installed package (`_many_segment_env`).

    Args:
        scenario: the MaMuJoCo scenario, e.g. ``"HalfCheetah"`` or ``"ManySegmentAnt"``.
        agent_conf: the factorization, e.g. ``"2x3"``.
        agent_obsk: how many joints away each agent observes (MaMuJoCo's default, 1).
        render_mode: ``"human"``, ``"rgb_array"``, ``"depth_array"`` or ``None``; also set on the
            MaMuJoCo env, which does not record it itself (wrappers such as SuperSuit read it).
        **kwargs: passed to the underlying Gymnasium MuJoCo env (``max_episode_steps``,
            ``xml_file``, reward weights, ...); arguments that change its observation space break
            MaMuJoCo's factorization.

    Example:
        >>> task = MaMuJoCoTask("HalfCheetah", "2x3")
        >>> task.protagonists, task.action_spaces["agent_0"].shape, task.state_space.shape
        (('agent_0', 'agent_1'), (3,), (17,))

    """

    def __init__(
        self,
        scenario: str,
        agent_conf: str | None,
        *,
        agent_obsk: int | None = 1,
        render_mode: str | None = None,
        **kwargs: Any,
    ) -> None:
        from gymnasium_robotics import mamujoco_v1

        kwargs.setdefault("disable_env_checker", True)  # the game checks actions itself
        self._assets: tempfile.TemporaryDirectory[str] | None = None
        gym_env = None
        if scenario in _MANY_SEGMENT:  # a generated model: see _many_segment_env
            self._assets = tempfile.TemporaryDirectory(prefix="advgame-mamujoco-")
            gym_env = _many_segment_env(
                scenario, agent_conf, self._assets.name, render_mode=render_mode, **kwargs
            )
            kwargs = {}
        self.env = mamujoco_v1.parallel_env(
            scenario,
            agent_conf,
            agent_obsk=agent_obsk,
            render_mode=render_mode,
            gym_env=gym_env,
            **kwargs,
        )
        self.env.render_mode = render_mode
        _fix_observation_layout(self.env)
        self.scenario = scenario
        self.agent_conf = agent_conf
        self.protagonists = tuple(self.env.possible_agents)
        self.observation_spaces = {a: self.env.observation_space(a) for a in self.protagonists}
        self.action_spaces = {a: self.env.action_space(a) for a in self.protagonists}
        single = self.env.single_agent_env
        self.state_space = single.observation_space  # env.state() is the single-agent observation
        self.max_episode_steps = single.spec.max_episode_steps if single.spec else None
        if self.max_episode_steps is None:  # CoupledHalfCheetah: a bare TimeLimit, no spec
            self.max_episode_steps = getattr(single, "_max_episode_steps", None)
        self._first = self.protagonists[0]
        self._sim: MujocoSim | None = None

    def reset(self, seed: int | None) -> tuple[dict[str, Any], dict[str, Any]]:
        """Reset the MaMuJoCo env with `seed`; the info is a copy of the agents' shared one."""
        obs, infos = self.env.reset(seed=seed)
        return obs, dict(infos[self._first])

    def step(self, actions: Mapping[str, Any]) -> StepResult:
        """Step every agent at once; return the team reward once and a copy of the shared info.

        Raises:
            AdvgameError: if MaMuJoCo gave the agents different rewards (it never should: the
                team payoff would be ill-defined).

        """
        obs, rewards, terms, truncs, infos = self.env.step(actions)
        reward = rewards[self._first]
        for agent, r in rewards.items():
            if r is not reward and r != reward:
                raise AdvgameError(
                    f"MaMuJoCo gave {agent!r} reward {r!r} but {self._first!r} {reward!r}; "
                    "a team task needs one shared reward. Check the installed gymnasium-robotics."
                )
        info = dict(infos[self._first])
        return obs, float(reward), 0.0, any(terms.values()), any(truncs.values()), info

    def state(self, observations: Mapping[str, Any]) -> Any:
        """The global state (MaMuJoCo's ``state()``: the single-agent observation)."""
        return self.env.state()

    @property
    def sim(self) -> MujocoSim:
        """The MuJoCo handle on the one model all agents share.

        Shape changes (``Param("length")``) read the model file (for a ManySegment robot, the one
        generated for this task, kept until `close`).
        """
        if self._sim is None:
            inner = self.env.single_agent_env.unwrapped
            path = getattr(inner, "fullpath", None)
            self._sim = MujocoSim(inner, path if path and os.path.exists(path) else None)
        return self._sim

    def render(self) -> Any:
        """Render through the underlying Gymnasium MuJoCo env."""
        return self.env.render()

    def close(self) -> None:
        """Close the MaMuJoCo env (and remove a generated model file)."""
        self.env.close()
        if self._assets is not None:
            self._assets.cleanup()


_MANY_SEGMENT = {"ManySegmentAnt": "Ant-v5", "ManySegmentSwimmer": "Swimmer-v5"}
"""MaMuJoCo's generated robots and the Gymnasium env that loads their model file."""


def _many_segment_env(scenario: str, agent_conf: str | None, folder: str, **kwargs: Any) -> Any:
    """The single-agent env of a ManySegment robot, its model generated into `folder`.

    MaMuJoCo generates these models into one fixed file inside its installed package and deletes
    it once loaded, so two processes building the same robot at once (an evaluation pool) delete
    each other's file, and a read-only install cannot build them at all. The same upstream
    generator writes here into a private folder instead, and MaMuJoCo gets the env as ``gym_env``.
    """
    from gymnasium_robotics.envs.multiagent_mujoco import many_segment_ant, many_segment_swimmer

    agents, _, per_agent = (agent_conf or "").partition("x")
    if not (agents.isdigit() and per_agent.isdigit()) or int(agents) * int(per_agent) < 1:
        raise ConfigError(
            f"{scenario} needs agent_conf '<agents>x<segments per agent>' (e.g. '2x3'), "
            f"got {agent_conf!r}."
        )
    segments = int(agents) * int(per_agent)
    path = os.path.join(folder, f"{scenario}_{segments}_segments.xml")
    generate = many_segment_ant if scenario == "ManySegmentAnt" else many_segment_swimmer
    generate.gen_asset(n_segs=segments, asset_path=path)
    return gym.make(_MANY_SEGMENT[scenario], xml_file=path, **kwargs)


def _fix_observation_layout(env: Any) -> None:
    """Give every agent the same observation layout in every instance of the env.

    MaMuJoCo orders the joints an agent observes by label. Pusher labels two joints
    ``"r_wrist_roll_joint"``, so their order, and with it ``agent_0``'s observation layout, follows
    set iteration order: it differs between two envs of one process (and between runs). Ties are
    broken here by action and position index; where labels are unique (every other robot) this is
    MaMuJoCo's own order.
    """
    changed = False
    for k_dict in getattr(env, "k_dicts", ()):  # absent when the task is single-agent
        for k, nodes in k_dict.items():
            ordered = sorted(nodes, key=lambda n: (n.label, str(n.act_ids), str(n.qpos_ids)))
            if ordered != nodes:
                k_dict[k] = ordered
                changed = True
    if changed:  # the cached global-state -> local-observation map follows the layout
        env.observation_factorization = env.create_observation_mapping()


def make_task(scenario: str, agent_conf: str | None, **kwargs: Any) -> MaMuJoCoTask:
    """A MaMuJoCo factorization as a task base (the registry's entry point)."""
    return MaMuJoCoTask(scenario, agent_conf, **kwargs)


def _force(scenario: str) -> ForceDisruptor:
    bodies, axes, bound = FORCES[scenario]
    return ForceDisruptor(bodies=bodies, axes=axes, max_force=bound)


_PARTIAL: dict[str, Any] = {
    "state": ObservationDisruptor,
    "action": ActionDisruptor,
    "reward": RewardDisruptor,
}
"""Disruptor spec class per kind of the paper's partial attacks."""


def _partial(kind: str, spec: Any) -> Preset:
    return Preset(
        (spec,),
        {spec.agent: GaussianAdversary(std=0.1)},
        f"paper: partial {kind} noise N(0, 0.1) every step, on {FIRST_AGENT} only",
    )


def _on_all(preset: Preset) -> Preset:
    return dataclasses.replace(preset, description=preset.description + ", on every agent")


def presets(scenario_id: str) -> dict[str, Preset]:
    """The presets of MaMuJoCo scenario `scenario_id` (see the module docstring)."""
    if scenario_id not in VARIANTS:
        raise UnknownScenarioError(
            f"No MaMuJoCo scenario {scenario_id!r}.{did_you_mean(scenario_id, VARIANTS)} "
            f"Known: {sorted(VARIANTS)}."
        )
    scenario = VARIANTS[scenario_id].scenario
    first = (FIRST_AGENT,)
    paper = gaussian_presets()
    return {
        "default": Preset(
            (ObservationDisruptor(eps=0.1), ActionDisruptor(eps=0.1)),
            description="bounded observation and action adversaries on every agent, ε = 0.1",
        ),
        "full": Preset(
            (
                ObservationDisruptor(eps=0.1),
                RewardDisruptor(eps=0.1),
                ActionDisruptor(eps=0.1),
                dynamics_shift(),
                _force(scenario),
            ),
            description="observation, reward, action on every agent; dynamics ±20 %; forces on "
            + ", ".join(FORCES[scenario][0]),
        ),
        "partial": Preset(
            (ObservationDisruptor(eps=0.1, targets=first), ActionDisruptor(eps=0.1, targets=first)),
            description=f"partial attack: observation and action adversaries (ε = 0.1) on {FIRST_AGENT} only",
        ),
        "state-gauss-0.1": _on_all(paper["state-gauss-0.1"]),
        "action-gauss-0.1": _on_all(paper["action-gauss-0.1"]),
        "reward-gauss-0.1": _on_all(paper["reward-gauss-0.1"]),
        **{
            f"{kind}-gauss-0.1-partial": _partial(kind, cls(bounded=False, targets=first))
            for kind, cls in _PARTIAL.items()
        },
    }
