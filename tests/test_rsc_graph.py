"""RSC's causal graph on systems whose true graph is known, and on the real causal tasks.

`ColourPoint` has a point ``x`` moved by the action, a side ``s`` (continuous, fixed for the
episode) and a colour ``c = sign(s)`` that goes with the side in every transition, as the cube's
colour goes with its side in RS-LiftCausal's training correlation. The true graph: ``x' ← x, a``;
``s' ← s``; ``c' ← c`` (an identity edge: the colour stays the colour); ``r ← x, s``. The side
predicts the next colour as well as the colour itself does, so only the graph's treatment of a
variable's own past keeps ``c → c'``; and ``r = −(x − s)²`` needs the side's magnitude, so the
colour is no stand-in for it.

Every check can fail: a graph that drops ``c → c'`` (the bug of the RS-LiftCausal runs before
6 Dec, whose next colours were one fixed colour the data never shows) predicts one colour for
every row; one that keeps ``s → c'`` follows the side when the perturbation moves the colour.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from gymnasium import spaces
from stable_baselines3.common.vec_env import DummyVecEnv

from advgame.agents.rsc.config import RSCConfig
from advgame.agents.rsc.model import CausalWorldModel, perturb_states
from advgame.agents.rsc.rsc import one_step_samples

pytestmark = pytest.mark.usefixtures("one_torch_thread")
X, S, C, A = 0, 1, 2, 3  # inputs: x, side, colour, action
NEXT_X, NEXT_S, NEXT_C, REWARD = 0, 1, 2, 3  # outputs: x', s', c', r


class ColourPoint(gym.Env):
    """A point ``x`` beside a side ``s`` in ±[0.5, 1] and its colour ``c = sign(s)``."""

    observation_space = spaces.Box(-2.0, 2.0, (3,), np.float32)
    action_space = spaces.Box(-1.0, 1.0, (1,), np.float32)

    def __init__(self) -> None:
        self.x, self.side, self.t = 0.0, 1.0, 0

    def _obs(self) -> np.ndarray:
        return np.array([self.x, self.side, np.sign(self.side)], dtype=np.float32)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        sign = 1.0 if self.np_random.random() < 0.5 else -1.0
        self.x, self.side, self.t = float(self.np_random.uniform(-1, 1)), 0.0, 0
        self.side = sign * float(self.np_random.uniform(0.5, 1.0))
        return self._obs(), {}

    def step(self, action):
        reward = -((self.x - self.side) ** 2)
        self.x = float(np.clip(self.x + 0.3 * float(np.asarray(action).ravel()[0]), -1, 1))
        self.t += 1
        return self._obs(), reward, False, self.t >= 25, {}


@pytest.fixture(scope="module")
def trained():
    """An RSC whose world model trained 3,000 updates on 2,000 random ColourPoint transitions."""
    th.set_num_threads(1)
    options = {"net_arch": (16, 16), "batch_size": 128, "learning_starts": 2000}
    model = RSCConfig(**options).make_model(DummyVecEnv([ColourPoint]), seed=0, total_steps=2000)
    model.learn(2000)
    for _ in range(3000):
        model.update_world_model(128)
    return model


def test_the_graph_is_the_true_one_identity_edge_included(trained) -> None:
    # A true edge settles where dropping it costs as much as the sparsity term: P(absent) ≈
    # λ / (the loss it saves). ``a → x'`` saves little (0.3·a beside x) and sits near 0.9
    # (0.89-0.92 over seeds 0-2 and 2,000-4,000 updates, 7 Dec), so its bar is 0.8.
    edges = trained.world_model.edge_probabilities().detach()
    for output, parents in {NEXT_X: (X, A), NEXT_S: (S,), NEXT_C: (C,), REWARD: (X, S)}.items():
        for i in range(4):
            if i in parents:
                assert float(edges[output, i]) > 0.8, (output, i, edges[output])
            else:
                assert float(edges[output, i]) < 0.2, (output, i, edges[output])


def test_every_output_is_predicted_under_the_graph_augmentation_uses(trained) -> None:
    th.manual_seed(3)
    pool = one_step_samples(trained.replay_buffer, 1024)
    errors = trained.world_model.mode_errors(
        pool.observations, pool.actions, pool.next_observations, pool.rewards
    )
    assert float(errors.max()) < 0.05, errors  # standardised: 1 is no better than the mean


def test_augmented_next_states_stay_in_the_datas_support(trained) -> None:
    th.manual_seed(4)
    pool = one_step_samples(trained.replay_buffer, 1024)
    aug = trained.augment(pool, 1024)
    colour = aug.observations[:, C]
    # the perturbation moved some colours away from their side: the next colour follows the
    # colour (its one parent), not the side, and is one the data has (±1)
    moved = th.sign(colour) != th.sign(aug.observations[:, S])
    assert int(moved.sum()) > 50
    next_colour = aug.next_observations[:, NEXT_C]
    assert float((next_colour - th.sign(colour)).abs().max()) < 0.1
    side = aug.observations[:, S]
    assert float((aug.next_observations[:, NEXT_S] - side).abs().max()) < 0.1


def test_self_edges_are_kept_unless_asked_and_the_draws_are_checked() -> None:
    model = CausalWorldModel(3, 1)
    model.graph_logits.data.fill_(-20.0)  # every learned edge absent
    assert model.mode_graph()[:3, :3].equal(th.eye(3)) and model.mode_graph()[3].sum() == 0
    old = CausalWorldModel(3, 1, graph_draws="relaxed", keep_self_edges=False)
    old.graph_logits.data.fill_(-20.0)
    assert old.mode_graph().sum() == 0
    with pytest.raises(ValueError, match="graph_draws"):
        CausalWorldModel(3, 1, graph_draws="soft")


def test_hard_draws_give_the_score_functions_gradient() -> None:
    """The logits' gradient is ``mean (L − b)(m − σ(φ))``, recomputed here from the same draws."""
    th.manual_seed(0)
    model = CausalWorldModel(2, 1, hidden=8)
    obs, actions = th.randn(64, 2), th.randn(64, 1)
    next_obs, rewards = obs + 0.1 * actions, obs[:, 0] ** 2
    state = th.random.get_rng_state()
    nll, _ = model.losses(obs, actions, next_obs, rewards)
    nll.backward()
    got = model.graph_logits.grad.clone()
    th.random.set_rng_state(state)  # the same edge draws again
    graph = model.draw_graph(64)  # the loss's own draws, one graph per row
    assert graph.shape == (64, 3, 3)
    x = model.inputs.normalize(th.cat([obs, actions], dim=1))
    y = model.targets.normalize(th.cat([next_obs, rewards.reshape(-1, 1)], dim=1))
    with th.no_grad():
        loss = (model(x, graph) - y) ** 2 / 2
    baseline = (loss.sum(dim=0, keepdim=True) - loss) / 63
    p = model.edge_probabilities().detach()
    want = ((loss - baseline).unsqueeze(2) * (graph - p)).mean(dim=0) * (1 - model.kept)
    # the prediction loss also reaches φ through nothing else: the draws are not differentiable
    assert th.allclose(got, want, atol=1e-6), (got, want)
    assert float(nll.detach()) == pytest.approx(float(loss.sum(dim=1).mean()), rel=1e-5)


def test_hard_draws_are_bernoulli_and_the_batched_forward_is_per_row() -> None:
    """`draw_graph` draws each edge at its probability; `forward` on a per-row graph gives
    each row what the single-graph forward gives it alone, and what each output's MLP gives."""
    th.manual_seed(3)
    model = CausalWorldModel(3, 2, hidden=8)
    model.graph_logits.data = th.randn_like(model.graph_logits) * 2
    graph = model.draw_graph(20_000)
    p = model.edge_probabilities().detach()
    assert float((graph.mean(dim=0) - p).abs().max()) < 0.02  # 4σ of a 20k-row mean is 0.014
    assert graph[:, :3, :3].diagonal(dim1=1, dim2=2).eq(1).all()  # kept edges always drawn
    x = th.randn(5, 5)
    rows = model(x, graph[:5])
    for r in range(5):
        lone = model(x[r : r + 1], graph[r])
        assert th.allclose(rows[r], lone[0], atol=1e-6)
    # the same numbers as each output's MLP written out (the form before 7 Dec's session 40,
    # which the released RS-LiftCausal agents trained with)
    masked = x.unsqueeze(1) * th.maximum(graph[:5], model.kept)
    h = th.relu(th.einsum("boi,oih->boh", masked, model.w1) + model.b1)
    h = th.relu(th.einsum("boh,ohk->bok", h, model.w2) + model.b2)
    assert th.allclose(rows, th.einsum("boh,oh->bo", h, model.w3) + model.b3, atol=1e-5)
    assert th.allclose(model(x, graph[:5].contiguous()), rows, atol=1e-6)  # any layout


def _transitions(
    scenario: str, preset: str, episodes: int = 4, steps: int = 100
) -> tuple[th.Tensor, ...]:
    """Random-action transitions of a causal task under a correlation (the preset's own
    workspace adversary sets the features at each reset)."""
    import advgame
    from advgame.core.views import SingleAgentView

    game = advgame.make(scenario, preset=preset, max_episode_steps=steps)
    env = SingleAgentView(game, "protagonist", dict(game.preset.adversaries))
    env.action_space.seed(0)
    rows: list[tuple[np.ndarray, ...]] = []
    for episode in range(episodes):
        obs, _ = env.reset(seed=episode)
        done = False
        while not done:
            action = env.action_space.sample()
            nxt, reward, terminated, truncated, _ = env.step(action)
            rows.append((obs, action, nxt, np.float32(reward)))
            obs, done = nxt, terminated or truncated
    env.close()
    return tuple(
        th.as_tensor(np.array(column), dtype=th.float32) for column in zip(*rows, strict=True)
    )


def test_on_rs_liftcausal_the_colour_stays_the_colour_in_augmented_rows() -> None:
    """The released RSC agents' failure, on the real task: after training, every augmented next
    state's colour is the augmented state's own (each channel 0 or 1, as in the data), not one
    fixed colour and not the one the cube's side would give."""
    th.manual_seed(0)
    obs, actions, next_obs, rewards = _transitions("RS-LiftCausal", "spurious-xnr")
    colour = slice(obs.shape[1] - 3, obs.shape[1])  # object-state's last three: the cube's RGB
    assert set(obs[:, colour].unique().tolist()) == {0.0, 1.0}  # red and green both seen
    model = CausalWorldModel(obs.shape[1], actions.shape[1], hidden=16)
    generator = np.random.default_rng(0)
    for _ in range(1000):
        rows = th.as_tensor(generator.integers(0, len(obs), 128))
        model.update(obs[rows], actions[rows], next_obs[rows], rewards[rows])
    edges = model.edge_probabilities().detach()
    for channel in range(colour.start, colour.stop - 1):  # R and G (B is 0 throughout)
        assert float(edges[channel, channel]) > 0.9, edges[channel, channel]
    states, _ = perturb_states(obs, len(obs))
    predicted, _ = model.predict(states, actions)
    shown = states[:, colour].round()
    assert float((predicted[:, colour] - shown).abs().max()) < 0.1
    recoloured = (shown != obs[:, colour]).any(dim=1)
    assert int(recoloured.sum()) > 0  # Eq. 7 moved some colours, and they stayed moved


def test_clipped_augmentation_stays_inside_the_range_the_model_trained_on(trained) -> None:
    th.manual_seed(5)
    pool = one_step_samples(trained.replay_buffer, 1024)
    stats = trained.world_model.targets
    data = th.cat([pool.next_observations, pool.rewards], dim=1)
    assert bool(
        (stats.low <= data.min(0).values).all() and (stats.high >= data.max(0).values).all()
    )
    states = pool.observations * 3.0  # far outside what the world model has seen
    trained.world_model.clip_to_support = False
    free = th.cat(trained.world_model.predict(states, pool.actions), dim=1)
    trained.world_model.clip_to_support = True
    try:
        clipped = th.cat(trained.world_model.predict(states, pool.actions), dim=1)
    finally:
        trained.world_model.clip_to_support = False
    outside = (free < stats.low) | (free > stats.high)
    assert int(outside.sum()) > 0  # so the clip has something to do
    assert bool(((clipped >= stats.low) & (clipped <= stats.high)).all())
    assert clipped[~outside].equal(free[~outside])


def test_a_world_model_saved_without_its_range_loads_and_clips_nothing() -> None:
    model = CausalWorldModel(3, 1)
    old = {k: v for k, v in model.state_dict().items() if not k.endswith(("low", "high"))}
    fresh = CausalWorldModel(3, 1, clip_to_support=True)
    fresh.load_state_dict(old)  # strict: the range is filled in, not missing
    assert th.isinf(fresh.targets.low).all() and th.isinf(fresh.targets.high).all()
    obs, actions = th.randn(8, 3), th.randn(8, 1)
    fresh.clip_to_support = False
    free = th.cat(fresh.predict(obs, actions), dim=1)
    fresh.clip_to_support = True
    assert th.cat(fresh.predict(obs, actions), dim=1).equal(free)


def test_on_rs_doorcausal_clipped_augmented_rows_stay_inside_the_datas_range() -> None:
    """The door campaign's RSC (`clip_to_support`): on real RS-DoorCausal transitions every
    augmented next state and reward lies inside the range of the data, where the unclipped
    model's predictions leave it (joint accelerations, docs/causal.md)."""
    th.manual_seed(0)
    obs, actions, next_obs, rewards = _transitions("RS-DoorCausal", "spurious-hhl", 2, 100)
    model = CausalWorldModel(obs.shape[1], actions.shape[1], hidden=16)
    generator = np.random.default_rng(0)
    for _ in range(300):
        rows = th.as_tensor(generator.integers(0, len(obs), 128))
        model.update(obs[rows], actions[rows], next_obs[rows], rewards[rows])
    data = th.cat([next_obs, rewards.reshape(-1, 1)], dim=1)
    low, high = data.min(0).values, data.max(0).values
    states, _ = perturb_states(obs, len(obs))
    free = th.cat(model.predict(states, actions), dim=1)
    assert bool(((free < low) | (free > high)).any())
    model.clip_to_support = True
    clipped = th.cat(model.predict(states, actions), dim=1)
    assert bool(((clipped >= low) & (clipped <= high)).all())
