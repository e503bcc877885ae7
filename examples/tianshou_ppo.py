"""Tianshou 2.0: one PPO per agent on an advgame game, through Tianshou's PettingZooEnv.

Tianshou's `PettingZooEnv` takes the AEC form (`parallel_to_aec`) and asserts that every agent
has the same observation and action space, so the game is padded with SuperSuit first (each
agent's own PPO learns on the padded spaces; padded action entries are dropped). Tianshou 2.0.1
cannot be installed beside advgame's lock (its virtualenv needs filelock<4): this runs in an
environment of its own (examples/tianshou-requirements.txt; tests/test_interop_clients.py
builds it).

Measured with tianshou 2.0.1, three adapters make it train (docs/interop.md says more):
without an action mask in the observation, collecting fails inside ``MultiAgentPolicy.forward``,
which reads ``batch.obs_next`` while actions are computed (that batch has none), so
`advgame.interop.ActionMaskObservations` gives each agent an all-ones mask (`PettingZooEnv`
passes a mask only for ``{"observation", "action_mask"}`` observations or a ``Discrete`` action
space). With a mask, Tianshou hands each network the whole observation ``Batch`` (``agent_id``,
``obs``, ``mask``), so the actor and the critic read its ``obs`` field through `ObsField`. And
the collector applies ``MultiAgentPolicy``'s action mapping, none, so SuperSuit's
``clip_actions_v0`` clips each action into its agent's space.
"""

import copy
from typing import Any

import supersuit as ss
import torch
from pettingzoo.utils.conversions import parallel_to_aec
from tianshou.algorithm import PPO
from tianshou.algorithm.modelfree.reinforce import ProbabilisticActorPolicy
from tianshou.algorithm.multiagent.marl import MultiAgentOnPolicyAlgorithm
from tianshou.algorithm.optim import AdamOptimizerFactory
from tianshou.data import Batch, Collector, VectorReplayBuffer
from tianshou.env import DummyVectorEnv
from tianshou.env.pettingzoo_env import PettingZooEnv
from tianshou.trainer import OnPolicyTrainerParams
from tianshou.utils.net.common import MLP, ModuleWithVectorOutput, Net
from tianshou.utils.net.continuous import ContinuousActorProbabilistic
from torch.distributions import Distribution, Independent, Normal

import advgame
from advgame.interop import ActionMaskObservations


class ObsField(ModuleWithVectorOutput):
    """`module` applied to the ``obs`` field of the observation Batch (beside agent_id, mask)."""

    def __init__(self, module: ModuleWithVectorOutput) -> None:
        super().__init__(module.get_output_dim())
        self.module = module

    def forward(self, obs: Batch, *args: Any, **kwargs: Any) -> Any:
        """Run `module` on ``obs.obs``, passing any other argument (the actor's state) on."""
        return self.module(obs.obs, *args, **kwargs)


def make_env() -> PettingZooEnv:
    """The game, clipped, padded to one space for all agents, with an all-ones mask, as AEC."""
    game = advgame.make("HalfCheetah-v5", preset="default", max_episode_steps=25)
    padded = ss.pad_action_space_v0(ss.pad_observations_v0(ss.clip_actions_v0(game)))
    return PettingZooEnv(parallel_to_aec(ActionMaskObservations(padded)))


def dist(loc_scale: tuple[torch.Tensor, torch.Tensor]) -> Distribution:
    """A diagonal Gaussian over the action's components, from the actor's (mean, std)."""
    return Independent(Normal(*loc_scale), 1)


def ppo(env: PettingZooEnv) -> PPO:
    """One agent's PPO: a Gaussian actor and a value critic, each one hidden layer of 64."""
    obs_shape, act_shape = env.observation_space["observation"].shape, env.action_space.shape
    actor = ContinuousActorProbabilistic(
        preprocess_net=ObsField(Net(state_shape=obs_shape, hidden_sizes=[64])),
        action_shape=act_shape,
    )
    critic = ObsField(MLP(input_dim=obs_shape[0], output_dim=1, hidden_sizes=[64]))
    policy = ProbabilisticActorPolicy(
        actor=actor,
        dist_fn=dist,
        action_space=env.action_space,
        observation_space=env.observation_space,
        # the collector maps actions with MultiAgentPolicy's settings (no scaling, no bound),
        # never these: SuperSuit's clip_actions_v0 bounds them to the game's spaces instead
        action_scaling=False,
        action_bound_method=None,
    )
    return PPO(policy=policy, critic=critic, optim=AdamOptimizerFactory(lr=3e-4))


torch.manual_seed(0)
env = make_env()
algorithm = MultiAgentOnPolicyAlgorithm(algorithms=[ppo(env) for _ in env.agents], env=env)
initial = {
    a: copy.deepcopy(dict(algorithm.get_algorithm(a).named_parameters())) for a in env.agents
}
train_envs = DummyVectorEnv([make_env, make_env])
train_envs.seed(0)
collector = Collector(algorithm, train_envs, VectorReplayBuffer(600, len(train_envs)))
result = algorithm.run_training(
    OnPolicyTrainerParams(
        training_collector=collector,
        max_epochs=2,
        epoch_num_steps=300,
        collection_step_num_env_steps=300,
        update_step_num_repetitions=1,
        batch_size=100,
        test_in_training=False,
        show_progress=False,
        verbose=False,
    )
)
# an agent trained if every one of its parameters (actor, log-std, critic) moved from its start
trained = [
    agent
    for agent in env.agents
    if all(
        not torch.equal(value, initial[agent][name])
        for name, value in algorithm.get_algorithm(agent).named_parameters()
    )
]
print("trained agents:", sorted(trained), "update steps:", result.update_step)
