"""The ecosystem's own multi-agent clients train an advgame game: every example in examples/ runs.

SuperSuit + Stable-Baselines3 and TorchRL are in the lock (the ``all`` extra) and run in this
environment. RLlib and Tianshou cannot be installed beside the lock (their pins conflict with
it; each requirements file quotes pip's message), so each runs in an environment of its own,
layered over this one: a venv whose ``.pth`` adds this environment's site-packages after its
own, holding only the client's pinned packages (examples/<client>-requirements.txt). It is
built once under ``.venv-clients/`` and rebuilt when its requirements file changes.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import numpy as np
import pytest
from gymnasium import spaces

import advgame
from advgame.interop import ActionMaskObservations, FixedInfos

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"


def _run(python: Path | str, script: str, timeout: int = 900) -> str:
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": ""}
    proc = subprocess.run(
        [str(python), str(EXAMPLES / script)],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
    )
    assert proc.returncode == 0, f"{script} failed:\n{proc.stdout[-2000:]}\n{proc.stderr[-4000:]}"
    return proc.stdout


def _client_python(name: str) -> Path:
    """The interpreter of the client's own environment, built (or reused) under .venv-clients/."""
    requirements = EXAMPLES / f"{name}-requirements.txt"
    parent = sysconfig.get_paths()["purelib"]  # this environment's site-packages
    digest = hashlib.sha256(requirements.read_bytes() + parent.encode()).hexdigest()
    venv = ROOT / ".venv-clients" / name
    python, stamp = venv / "bin" / "python", venv / "built-from"
    if stamp.exists() and stamp.read_text() == digest:
        return python
    shutil.rmtree(venv, ignore_errors=True)
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=300)
    site = subprocess.run(
        [str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        capture_output=True, text=True, check=True,
    ).stdout.strip()  # fmt: skip
    # after the venv's own packages: the client's pins shadow the lock's, the rest is shared
    Path(site, "_advgame_parent.pth").write_text(f"import site; site.addsitedir({parent!r})\n")
    pip = [str(python), "-m", "pip", "install", "-q", "--no-deps", "-r", str(requirements)]
    proc = subprocess.run(pip, capture_output=True, text=True, timeout=1200)
    assert proc.returncode == 0, f"installing {requirements.name} failed:\n{proc.stderr[-3000:]}"
    stamp.write_text(digest)
    return python


def test_supersuit_sb3_pipeline_trains_one_shared_policy() -> None:
    out = _run(sys.executable, "supersuit_sb3.py")
    assert "trained 2304 agent-moves over 6 agent-environments" in out, out


def test_torchrl_ippo_trains_every_group() -> None:
    pytest.importorskip("torchrl", reason="the torchrl extra: pip install -c constraints.txt '.[torchrl]'")  # fmt: skip
    out = _run(sys.executable, "torchrl_ippo.py")
    assert "trained groups: ['action_adversary', 'observation_adversary', 'protagonist']" in out


def test_rllib_ppo_trains_one_module_per_agent_in_its_own_environment() -> None:
    out = _run(_client_python("rllib"), "rllib_ppo.py")
    assert "modules trained: ['action_adversary', 'observation_adversary', 'protagonist']" in out


def test_tianshou_ppo_trains_one_policy_per_agent_in_its_own_environment() -> None:
    # the example prints the agents all of whose parameters moved from their initial values
    out = _run(_client_python("tianshou"), "tianshou_ppo.py")
    assert "trained agents: ['action_adversary', 'observation_adversary', 'protagonist']" in out


def test_fixed_infos_keeps_every_key_on_every_move() -> None:
    game = FixedInfos(advgame.make("HalfCheetah-v5", preset="default", max_episode_steps=3))
    _, infos = game.reset(seed=0)
    seen = [infos]
    while game.agents:
        *_, infos = game.step({a: game.action_space(a).sample() for a in game.agents})
        seen.append(infos)
    keys = {("acted", "true_reward", "true_cost", "payoff")}
    assert {tuple(i[a]) for i in seen for a in i} == keys
    assert all(type(v) is np.float32 for i in seen for a in i for v in i[a].values())
    acted = [i["observation_adversary"]["acted"] for i in seen[1:]]
    assert acted == [1.0, 0.0] * 3  # the sense move is the observation adversary's
    game.close()


def test_action_mask_observations_wraps_each_observation_and_nothing_else() -> None:
    def make() -> advgame.Game:
        return advgame.make("HalfCheetah-v5", preset="default", max_episode_steps=3)

    game, plain = ActionMaskObservations(make()), make()
    for agent in game.possible_agents:
        space = game.observation_space(agent)
        assert space is game.observation_spaces[agent]  # cached, as the game's own
        assert space["observation"] is game.env.observation_space(agent)
        assert space["action_mask"] == spaces.Box(0, 1, plain.action_space(agent).shape, np.int8)
    observations, _ = game.reset(seed=0)
    expected, _ = plain.reset(seed=0)
    rng = np.random.default_rng(0)
    while plain.agents:
        for agent, obs in observations.items():
            assert obs in game.observation_space(agent)
            assert np.all(obs["action_mask"] == 1)
            np.testing.assert_array_equal(obs["observation"], expected[agent])
        actions = {a: rng.uniform(-1, 1, plain.action_space(a).shape) for a in plain.agents}
        observations, *_ = game.step(actions)
        expected, *_ = plain.step(actions)
    assert not game.agents
    game.close()
    plain.close()
