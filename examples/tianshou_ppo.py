"""Tianshou 2.0: one PPO per agent on an advgame game, through Tianshou's PettingZooEnv.

Tianshou's `PettingZooEnv` takes the AEC form (`parallel_to_aec`) and asserts that every agent
has the same observation and action space, so the game is padded with SuperSuit first (each
agent's own PPO learns on the padded spaces; padded action entries are dropped). Tianshou 2.0.1
cannot be installed beside advgame's lock (its virtualenv needs filelock<4): this runs in an
environment of its own (examples/tianshou-requirements.txt; tests/test_interop_clients.py
builds it).

Measured with tianshou 2.0.1: collecting fails inside Tianshou, in
``MultiAgentPolicy.forward`` (``tmp_batch.obs_next`` is read while actions are computed, when
the batch has no ``obs_next``; the path is taken for every action space without an action mask,
i.e. every continuous one). tests/test_interop_clients.py runs this script and expects that
failure (strict), so a fixed Tianshou release shows up as a passing example.
"""

import supersuit as ss
import torch
from pettingzoo.utils.conversions import parallel_to_aec
from tianshou.algorithm import PPO
from tianshou.algorithm.modelfree.reinforce import ProbabilisticActorPolicy
from tianshou.algorithm.multiagent.marl import MultiAgentOnPolicyAlgorithm
from tianshou.algorithm.optim import AdamOptimizerFactory
from tianshou.data import Collector, VectorReplayBuffer
from tianshou.env import DummyVectorEnv
from tianshou.env.pettingzoo_env import PettingZooEnv
from tianshou.trainer import OnPolicyTrainerParams
from tianshou.utils.net.common import Net
from tianshou.utils.net.continuous import ContinuousActorProbabilistic, ContinuousCritic
from torch.distributions import Distribution, Independent, Normal

import advgame


def make_env() -> PettingZooEnv:
    game = advgame.make("HalfCheetah-v5", preset="default", max_episode_steps=25)
    return PettingZooEnv(parallel_to_aec(ss.pad_action_space_v0(ss.pad_observations_v0(game))))


def dist(loc: torch.Tensor, scale: torch.Tensor) -> Distribution:
    return Independent(Normal(loc, scale), 1)


def ppo(env: PettingZooEnv) -> PPO:
    obs_shape, act_shape = env.observation_space.shape, env.action_space.shape
    actor = ContinuousActorProbabilistic(
        preprocess_net=Net(state_shape=obs_shape, hidden_sizes=[64]), action_shape=act_shape
    )
    critic = ContinuousCritic(preprocess_net=Net(state_shape=obs_shape, hidden_sizes=[64]))
    policy = ProbabilisticActorPolicy(
        actor=actor,
        dist_fn=dist,
        action_space=env.action_space,
        observation_space=env.observation_space,
    )
    return PPO(policy=policy, critic=critic, optim=AdamOptimizerFactory(lr=3e-4))


torch.manual_seed(0)
env = make_env()
algorithm = MultiAgentOnPolicyAlgorithm(algorithms=[ppo(env) for _ in env.agents], env=env)
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
print("trained agents:", sorted(algorithm._dispatcher.algorithms), result.update_step)
