"""RLlib multi-agent PPO on an advgame game, through RLlib's own ParallelPettingZooEnv.

ray[rllib] 2.60 pins gymnasium 1.2.2 while advgame's lock has gymnasium 1.4.0, so this runs in an
environment of its own (examples/rllib-requirements.txt; tests/test_interop_clients.py builds it). Each
agent is mapped to an RLModule of its own: the protagonist side is one module, the adversary
side one module per adversary, because the two adversaries' action spaces differ (17 and 6).
RLModules accept heterogeneous spaces, so no padding is needed.
"""

import ray
from ray.rllib.algorithms.ppo import PPOConfig
from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec
from ray.rllib.core.rl_module.rl_module import RLModuleSpec
from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv
from ray.tune.registry import register_env

import advgame


def make_env(config: dict) -> ParallelPettingZooEnv:
    return ParallelPettingZooEnv(
        advgame.make("HalfCheetah-v5", preset="default", max_episode_steps=50)
    )


AGENTS = advgame.make("HalfCheetah-v5", preset="default").possible_agents
ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
register_env("advgame_halfcheetah", make_env)
config = (
    PPOConfig()
    .environment("advgame_halfcheetah")
    .framework("torch")
    .env_runners(num_env_runners=0, rollout_fragment_length=100)
    .learners(num_learners=0)
    .multi_agent(
        policies=set(AGENTS),  # one module per agent: protagonist and each adversary
        policy_mapping_fn=lambda agent_id, episode, **kwargs: agent_id,
    )
    .rl_module(
        rl_module_spec=MultiRLModuleSpec(rl_module_specs={a: RLModuleSpec() for a in AGENTS})
    )
    .training(train_batch_size=200, minibatch_size=100, num_epochs=2)
    .debugging(seed=0)
)
algo = config.build_algo()
for _ in range(2):  # two PPO iterations; every module (both sides) is updated
    result = algo.train()
learner = result["learners"]
trained = sorted(a for a in AGENTS if a in learner and "policy_loss" in learner[a])
print("modules trained:", trained)
assert trained == sorted(AGENTS), learner.keys()
algo.stop()
ray.shutdown()
