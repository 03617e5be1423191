"""Jitted ray-cast sensors: a 2-D laser scanner and a depth camera, for one env under `jit`
(`vmap` for a batch), on body poses from any physics backend.

Build a sensor once from a compiled model (names are resolved and checked then, so a typo is
a `ConfigError` at build time, never inside `jit`), then call it on body poses indexed by body
id, MuJoCo's `xpos`/`xquat` (an `mjx.Data`'s, or a backend's readout)::

    laser = LaserSpec(frame="base").build(model)
    ranges = laser_scan(laser, d.xpos, d.xquat)  # (360,)
    cam = DepthSpec(camera="overhead", width=64, height=48).build(model)
    depth, valid = depth_image(cam, d.xpos, d.xquat)  # (48, 64), (48, 64)
    points, valid = depth_pointcloud(cam, d.xpos, d.xquat)  # (3072, 3), (3072,)

Distances follow `mujoco.mj_multiRay` (the tests hold them to it): primitive geoms (plane,
sphere, capsule, ellipsoid, cylinder, box); invisible geoms (alpha 0) and geoms outside the
sensor's groups (default 0-2, what MuJoCo renders) or on excluded bodies are not seen.
"""

from openral_mjx.raycast.depth import (
    DepthCamera,
    DepthSpec,
    camera_intrinsics,
    depth_image,
    depth_pointcloud,
)
from openral_mjx.raycast.geoms import ALL_GROUPS, VISIBLE_GROUPS, GeomSet
from openral_mjx.raycast.laser import Laser, LaserSpec, laser_scan

__all__ = [
    "ALL_GROUPS",
    "VISIBLE_GROUPS",
    "DepthCamera",
    "DepthSpec",
    "GeomSet",
    "Laser",
    "LaserSpec",
    "camera_intrinsics",
    "depth_image",
    "depth_pointcloud",
    "laser_scan",
]
