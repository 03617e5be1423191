"""`laser_scan`: a 2-D laser scanner, a horizontal fan of rays from a body or site.

Beam i leaves the point `height_m` above the frame's origin (world +z) at bearing
`angle_min + i * 2 pi / n_beams` (counter-clockwise, from the frame's heading: its x axis
projected onto the horizontal plane), parallel to the floor, like a planar lidar on a mobile
base (ROS `LaserScan` conventions with `angle_min` = -pi by default). Ranges are metres along
the beam to the nearest visible geom, clamped to `max_range_m` where nothing is hit within it:
never NaN or inf. The robot's own bodies are excluded by default (the frame's top-level body and
everything attached to it), as the CPU original excluded the base with `mj_multiRay`'s
`bodyexclude`.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from openral_mjx.core.options import check
from openral_mjx.raycast import mount as mounts
from openral_mjx.raycast.geoms import VISIBLE_GROUPS, GeomSet, body_ids, static_bounds, subtree


@dataclasses.dataclass(frozen=True)
class LaserSpec:
    """What a laser scanner is; `build` resolves it against a model.

    Attributes:
        frame: body or site the scanner is mounted on.
        name: key of its readings (observations, recorded frames).
        n_beams: beams per scan, evenly spaced over a full turn.
        max_range_m: range reported where a beam hits nothing closer.
        height_m: beam plane above the frame's origin (world z).
        angle_min: bearing of beam 0 from the frame's heading (rad, counter-clockwise).
        groups: geom groups the beams see (MuJoCo's `geomgroup`).
        exclude: bodies whose geoms (and their descendants') the beams pass through; None:
            the robot carrying the frame (its top-level body's subtree; none for the world).
    """

    frame: str
    name: str = "scan"
    n_beams: int = 360
    max_range_m: float = 12.0
    height_m: float = 0.30
    angle_min: float = -math.pi
    groups: tuple[int, ...] = VISIBLE_GROUPS
    exclude: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        check(self.n_beams >= 1, f"laser {self.name!r}: n_beams={self.n_beams} must be >= 1")
        check(
            self.max_range_m > 0,
            f"laser {self.name!r}: max_range_m={self.max_range_m} must be > 0",
        )

    def build(self, model: mujoco.MjModel) -> Laser:
        return Laser(model, self)


class Laser:
    """A `LaserSpec` resolved against a model: beam directions and the geoms they can hit."""

    def __init__(self, model: mujoco.MjModel, spec: LaserSpec) -> None:
        what = f"laser {spec.name!r}"
        self.spec = spec
        self.mount = mounts.body_or_site(model, spec.frame, what)
        if spec.exclude is None:
            roots = [self.mount.root] if self.mount.root != 0 else []
        else:
            roots = body_ids(model, spec.exclude, what)
        excluded = subtree(model, roots) if roots else set()
        geoms = GeomSet.select(model, groups=spec.groups, exclude_bodies=excluded)
        if self.mount.static:  # cull static geoms that cannot meet the (static) beam plane
            origin = self.mount.pos + np.array([0.0, 0.0, spec.height_m])
            centre, radius = static_bounds(model)

            def reachable(g: int) -> bool:
                c, r = centre[g], radius[g]
                return bool(
                    abs(c[2] - origin[2]) <= r
                    and np.linalg.norm(c - origin) <= spec.max_range_m + r
                )

            geoms = geoms.keep(reachable)
        self.geoms = geoms
        self.angles = (
            spec.angle_min + np.arange(spec.n_beams) * (2 * np.pi / spec.n_beams)
        ).astype(np.float32)
        self.dirs = np.stack(
            [np.cos(self.angles), np.sin(self.angles), np.zeros(spec.n_beams)], axis=1
        ).astype(np.float32)

    @property
    def bodies(self) -> tuple[int, ...]:
        """Moving bodies whose poses the scan reads (ids into `xpos`/`xquat`)."""
        extra = () if self.mount.static else (self.mount.body,)
        return tuple(sorted(set(self.geoms.bodies) | set(extra)))

    @property
    def shape(self) -> tuple[int, ...]:
        return (self.spec.n_beams,)


def laser_scan(laser: Laser, xpos: jax.Array, xquat: jax.Array) -> jax.Array:
    """Ranges (n_beams,) float32 in metres, `max_range_m` where nothing is hit (never NaN/inf).

    `xpos` (nbody, 3) and `xquat` (nbody, 4) are body poses indexed by body id (MuJoCo's
    `xpos`/`xquat`); only `laser.bodies` are read. One env; `vmap` for a batch.
    """
    pos, rot = laser.mount.pose(xpos, xquat)
    origin = pos + jnp.array([0.0, 0.0, laser.spec.height_m], jnp.float32)
    # Heading: the frame's x axis projected onto the floor.
    cx, cy = rot[0, 0], rot[1, 0]
    n = jnp.sqrt(cx * cx + cy * cy)
    c, s = cx / jnp.maximum(n, 1e-12), cy / jnp.maximum(n, 1e-12)
    zero, one = jnp.zeros_like(c), jnp.ones_like(c)
    frame = jnp.stack(
        [jnp.stack([c, -s, zero]), jnp.stack([s, c, zero]), jnp.stack([zero, zero, one])]
    )
    dist = laser.geoms.cast(xpos, xquat, origin, frame, laser.dirs)
    max_range = jnp.float32(laser.spec.max_range_m)
    return jnp.where(dist < max_range, dist, max_range)
