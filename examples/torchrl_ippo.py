"""TorchRL: IPPO on an advgame game through TorchRL's own PettingZooWrapper.

TorchRL stacks the agents of one group into one tensor, so agents whose spaces differ cannot
share a group: here each agent is a group of its own (protagonist, observation adversary, action
adversary), each with its own actor, critic and `ClipPPOLoss` (IPPO). TorchRL builds its info
specs from the first reset, and a game's infos change keys between moves, so the game is wrapped
in `advgame.interop.FixedInfos`; its ``acted`` flag (whose action counted in a move: the sense
move is the observation adversary's alone) masks each group's PPO loss.
"""

import torch
from tensordict.nn import NormalParamExtractor, TensorDictModule, TensorDictSequential
from torch import nn
from torchrl.collectors import Collector
from torchrl.envs import DoubleToFloat, TransformedEnv
from torchrl.envs.libs.pettingzoo import PettingZooWrapper
from torchrl.modules import MLP, ProbabilisticActor, TanhNormal, ValueOperator
from torchrl.objectives import ClipPPOLoss, ValueEstimators

import advgame
from advgame.interop import FixedInfos

torch.manual_seed(0)
game = advgame.make("HalfCheetah-v5", preset="default", max_episode_steps=50)
groups = {agent: [agent] for agent in game.possible_agents}  # one group per agent
env = PettingZooWrapper(FixedInfos(game), group_map=groups, seed=0, device="cpu")
env = TransformedEnv(env, DoubleToFloat(in_keys=[(g, "observation") for g in groups]))


def actor(group: str) -> ProbabilisticActor:
    spec = env.full_action_spec[group, "action"]
    n_obs = env.observation_spec[group, "observation"].shape[-1]
    net = nn.Sequential(MLP(n_obs, 2 * spec.shape[-1], num_cells=[64, 64]), NormalParamExtractor())
    module = TensorDictModule(net, [(group, "observation")], [(group, "loc"), (group, "scale")])
    return ProbabilisticActor(
        module,
        in_keys=[(group, "loc"), (group, "scale")],
        out_keys=[(group, "action")],
        distribution_class=TanhNormal,
        distribution_kwargs={"low": spec.space.low, "high": spec.space.high},
        return_log_prob=True,
        log_prob_key=(group, "action_log_prob"),
        spec=spec,
    )


def critic(group: str) -> ValueOperator:
    n_obs = env.observation_spec[group, "observation"].shape[-1]
    return ValueOperator(
        MLP(n_obs, 1, num_cells=[64, 64]), [(group, "observation")], [(group, "state_value")]
    )


actors = {g: actor(g) for g in groups}
losses = {}
for g in groups:
    loss = ClipPPOLoss(actors[g], critic(g), entropy_coeff=0.0, normalize_advantage=False)
    loss.set_keys(
        reward=(g, "reward"),
        action=(g, "action"),
        sample_log_prob=(g, "action_log_prob"),
        value=(g, "state_value"),
        done=(g, "done"),
        terminated=(g, "terminated"),
    )
    loss.make_value_estimator(ValueEstimators.GAE, gamma=0.99, lmbda=0.95)
    losses[g] = loss
optimizers = {g: torch.optim.Adam(losses[g].parameters(), lr=3e-4) for g in groups}
collector = Collector(
    env, TensorDictSequential(*actors.values()), frames_per_batch=200, total_frames=600
)

for iteration, batch in enumerate(collector):  # 3 iterations, every side updated in each
    for g, loss in losses.items():
        with torch.no_grad():
            loss.value_estimator(
                batch,
                params=loss.critic_network_params,
                target_params=loss.target_critic_network_params,
            )
        acted = batch["next", g, "info", "acted"].bool().reshape(-1)  # this agent's moves only
        data = batch[acted]
        for _ in range(2):  # PPO epochs over this group's moves
            terms = loss(data)
            total = terms["loss_objective"] + terms["loss_critic"]
            optimizers[g].zero_grad()
            total.backward()
            optimizers[g].step()
    print(iteration, {g: round(float(batch["next", g, "reward"].sum()), 2) for g in groups})
collector.shutdown()
print("trained groups:", sorted(losses))
