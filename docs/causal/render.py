"""Render the training and test variants of RS-LiftCausal and RS-DoorCausal (docs/causal/*.png).

Run from the repository root: ``MUJOCO_GL=egl python docs/causal/render.py``. Each picture is
a 2 x 2 grid: columns are the two values of the causal feature, the top row is the paper's
default ``spurious_type`` (training) and the bottom row its reverse (test); ``spurious-none``
draws all four. The scene is set by the workspace adversary's setup move, as in a game, and
drawn off-screen by MuJoCo's renderer (the one robosuite's off-screen renderer wraps) with
robosuite's visual geoms only (group 1).
"""

from __future__ import annotations

import os
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import mujoco
import numpy as np
from PIL import Image, ImageDraw

import advgame

HERE = Path(__file__).resolve().parent
W, H = 320, 240
TASKS = {
    "RS-LiftCausal": (("y < 0", "y > 0"), ("xnr (train)", "xpr (reversed)"), "agentview"),
    "RS-DoorCausal": (("left", "right"), ("hhl (train)", "hhr (reversed)"), None),
}


def _camera(game: advgame.Game) -> mujoco.MjvCamera:
    """A free camera on the door, from the robot's side."""
    cam = mujoco.MjvCamera()
    sim = game.task.sim
    cam.lookat[:] = sim.data.xpos[sim.body_id("Door_main")] + np.array([0.0, 0.0, 0.25])
    cam.distance, cam.azimuth, cam.elevation = 1.6, 205.0, -20.0
    return cam


def grid(sid: str) -> Image.Image:
    """The four variants of `sid`, labelled."""
    sides, rows, camera = TASKS[sid]
    game = advgame.make(sid, preset="adversarial", max_episode_steps=2)
    renderer = mujoco.Renderer(game.task.sim.model, H, W)
    option = mujoco.MjvOption()
    option.geomgroup[:] = 0
    option.geomgroup[1] = 1
    out = Image.new("RGB", (2 * W, 2 * H), "white")
    sign = -1.0 if sid == "RS-LiftCausal" else 1.0  # xnr: red with y < 0; hhl: high with left
    for r, label in enumerate(rows):
        for c, side in enumerate(sides):
            causal = -1.0 if (sid == "RS-LiftCausal") == (c == 0) else 1.0
            spurious = sign * causal * (1.0 if r == 0 else -1.0)
            game.reset(seed=1)
            game.play({"workspace_adversary": np.array([causal, spurious], dtype=np.float32)})
            renderer.update_scene(
                game.task.sim.data, camera=camera or _camera(game), scene_option=option
            )
            tile = Image.fromarray(renderer.render())
            ImageDraw.Draw(tile).text((6, 6), f"{label}: {side}", fill="black")
            out.paste(tile, (c * W, r * H))
    renderer.close()
    game.close()
    return out


if __name__ == "__main__":
    for sid in TASKS:
        image = grid(sid).quantize(colors=256)  # a palette PNG: a third of the size
        image.save(HERE / f"{sid.removeprefix('RS-').lower()}.png", optimize=True)
