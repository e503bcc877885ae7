"""Capsule half-lengths edited in the live model, as OMPO edits them, with true collision bounds.

OMPO's non-stationary Hopper and Walker2d (Roythuly/OMPO, ``Non_stationary_env/hopper_random.py``
lines 26-30, ``walker2d_random.py`` lines 27-33) lengthen a capsule by writing the compiled
model's ``geom_size`` and move bodies by writing ``body_pos``, without recompiling: masses,
inertias and every other compile-time constant stay nominal. MuJoCo also computes each geom's
bounding radius and box at compile time (``geom_rbound``, ``geom_aabb`` and the body's
bounding-volume node in ``bvh_aabb``) and skips collision pairs whose bounds do not meet, so
after OMPO's edit alone the tips of a lengthened capsule can sink into the floor with no contact
(measured on Hopper-v5: a foot of half-length 0.6 tilted by 0.7 rad penetrates the floor by
5 mm and MuJoCo reports no contact). `CapsuleEdit` writes OMPO's arrays and the bounds a compile
of the edited geometry gives (``tests/test_ompo_tasks.py`` compares them with a `mujoco.MjSpec`
compile), so shapes collide as they look while the mass model stays OMPO's.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from advgame.errors import ConfigError

__all__ = ["ANCHORS", "CapsuleEdit"]

ANCHORS = ("centre", "base")
"""What stays in place when a capsule's half-length changes: its centre (the capsule grows at
both ends), or its base, the end at ``-z`` of the geom's frame (the body and its capsule slide
by the change along the capsule's axis and its child bodies slide back, so they stay put)."""


class CapsuleEdit:
    """The capsule of one body, resolved in a compiled model: ids, nominal values, edits.

    Args:
        model: the compiled `mujoco.MjModel` (the ids hold for any recompile of the same file).
        body: the body id.
        name: the body's name (for messages).
        anchor: one of `ANCHORS`.

    """

    def __init__(self, model: Any, body: int, name: str, anchor: str) -> None:
        import mujoco

        if anchor not in ANCHORS:
            raise ConfigError(f"anchor must be one of {ANCHORS}, got {anchor!r}.")
        first, count = int(model.body_geomadr[body]), int(model.body_geomnum[body])
        capsules = [
            g for g in range(first, first + count)
            if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_CAPSULE
        ]  # fmt: skip
        if not capsules:
            raise ConfigError(f"Body {name!r} has no capsule geom whose half-length could change.")
        self.body, self.geom, self.anchor = body, capsules[0], anchor
        self.node = int(model.body_bvhadr[body])
        if model.body_bvhnum[body] != 1 or model.bvh_nodeid[self.node] != self.geom:
            raise ConfigError(
                f"Body {name!r} has {model.body_bvhnum[body]} collision geoms; an in-place "
                "capsule edit supports a body whose capsule is its only one. Use "
                "Param('length', ...), which recompiles the model, for this body."
            )
        quat = model.geom_quat[self.geom]
        self.axis = np.zeros(3)
        """The capsule's axis in the body's frame."""
        mujoco.mju_rotVecQuat(self.axis, np.array([0.0, 0.0, 1.0]), quat)
        self.children = np.nonzero(model.body_parentid == body)[0]
        self.children = self.children[self.children != body]
        self.half = float(model.geom_size[self.geom, 1])
        """The nominal half-length."""
        self._nominal = {
            "size": model.geom_size[self.geom].copy(),
            "rbound": float(model.geom_rbound[self.geom]),
            "aabb": model.geom_aabb[self.geom].copy(),
            "bvh": model.bvh_aabb[self.node].copy(),
            "pos": model.body_pos[body].copy(),
            "children": model.body_pos[self.children].copy(),
        }

    def apply(self, model: Any, half: float) -> None:
        """Give the capsule half-length `half` in `model` (masses and inertias untouched)."""
        import mujoco

        g, radius = self.geom, float(model.geom_size[self.geom, 0])
        model.geom_size[g, 1] = half
        model.geom_rbound[g] = radius + half  # what the compiler gives a capsule
        model.geom_aabb[g, 3:] = (radius, radius, radius + half)
        model.bvh_aabb[self.node] = model.geom_aabb[g]
        if self.anchor == "base":
            slide = self.axis * (half - self.half)  # in the body's frame
            moved = np.zeros(3)
            mujoco.mju_rotVecQuat(moved, slide, model.body_quat[self.body])  # parent's frame
            model.body_pos[self.body] = self._nominal["pos"] + moved
            model.body_pos[self.children] = self._nominal["children"] - slide

    def restore(self, model: Any) -> None:
        """Write the nominal size, bounds and body positions back into `model`."""
        g, nom = self.geom, self._nominal
        model.geom_size[g] = nom["size"]
        model.geom_rbound[g] = nom["rbound"]
        model.geom_aabb[g] = nom["aabb"]
        model.bvh_aabb[self.node] = nom["bvh"]
        model.body_pos[self.body] = nom["pos"]
        model.body_pos[self.children] = nom["children"]
