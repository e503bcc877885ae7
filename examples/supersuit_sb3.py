"""PettingZoo's SB3 tutorial pipeline on an advgame game: SuperSuit's vectorisation + SB3 PPO.

SuperSuit turns every agent into one environment of a vector, so Stable-Baselines3 trains ONE
policy shared by all agents: the protagonist and both adversaries, the maximiser and the
minimisers of one payoff. The agents' spaces differ (the protagonist 17 -> 6, the observation
adversary 17 -> 17, the action adversary 17 -> 6), so SuperSuit pads them to one shape, and
`agent_indicator_v0` appends a one-hot agent id so that the shared network can tell the sides
apart. For one policy per side use advgame's own loop (`advgame train`) or a multi-agent client.
"""

import numpy as np
import supersuit as ss
from stable_baselines3 import PPO
from stable_baselines3.common.utils import set_random_seed

import advgame

game = advgame.make("HalfCheetah-v5", preset="default", max_episode_steps=100)
env = ss.agent_indicator_v0(ss.pad_action_space_v0(ss.pad_observations_v0(game)))
vec = ss.pettingzoo_env_to_vec_env_v1(env)  # 3 agents -> 3 environments
vec = ss.concat_vec_envs_v1(vec, 2, num_cpus=0, base_class="stable_baselines3")  # 6 in all
# SuperSuit 3.11's SB3 wrapper passes a seed on through a seed() that its ConcatVecEnv lacks, so
# PPO(seed=...) and vec.reset(seed=...) fail: seed torch, and the games through the inner vector.
set_random_seed(0)
vec.venv.reset(seed=0)
model = PPO("MlpPolicy", vec, n_steps=128, batch_size=128, n_epochs=2, device="cpu")
model.learn(total_timesteps=3 * 128 * vec.num_envs)  # 3 PPO iterations over both sides
print("trained", model.num_timesteps, "agent-moves over", vec.num_envs, "agent-environments")

# The trained shared policy plays every agent of a fresh game (its padded, indicated view).
game = advgame.make("HalfCheetah-v5", preset="default", max_episode_steps=100)
played = ss.agent_indicator_v0(ss.pad_action_space_v0(ss.pad_observations_v0(game)))
observations, infos = played.reset(seed=1)
true_return = 0.0
while played.agents:
    actions = {a: model.predict(observations[a], deterministic=True)[0] for a in played.agents}
    observations, rewards, terminations, truncations, infos = played.step(actions)
    true_return += infos["protagonist"].get("true_reward", 0.0)
print("protagonist's true return against the trained adversaries:", f"{true_return:.3f}")
assert np.isfinite(true_return)
