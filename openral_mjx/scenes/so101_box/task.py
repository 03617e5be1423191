"""`so101_box` task logic: reset layout, insertion (success) predicate, reward, episode factors.

Pure JAX functions of the options, one env's physics `Quantities` and a PRNG key, with no
backend in sight, so one definition runs on every physics backend. They read the quantities
`quantity_spec` declares, by the row indices below.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp

from openral_mjx.core import fixed_order as fo
from openral_mjx.core.rotations import quat_axis_z, rotate_inverse
from openral_mjx.physics import Quantities, QuantitySpec
from openral_mjx.physics.cameras import SensorSpec
from openral_mjx.scenes.so101_box.options import Pair, So101BoxOptions

# Rows of `Quantities.body_pos`/`body_quat` and of `Quantities.site_pos` (see `quantity_spec`).
TUBE, BLOCK = 0, 1
EE, GRASP, TUBE_END_A, TUBE_END_B = 0, 1, 2, 3

_CANDIDATES = 32  # (block, tube) layouts drawn per reset; the first valid one is used


def quantity_spec(ee_site: str, sensors: tuple[SensorSpec, ...]) -> QuantitySpec:
    """What the task and the observation read: tube and block poses; the end-effector, grasp
    and tube-end sites; the observed sensors (rows in the order of `TUBE`, ..., `TUBE_END_B`)."""
    return QuantitySpec(
        bodies=("tube", "block"),
        sites=(ee_site, "grasp", "tube_end_a", "tube_end_b"),
        sensors=sensors,
    )


def sample_layout(o: So101BoxOptions, key: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Block and tube (x, y, yaw) for one episode, never overlapping each other or the robot.

    Draws `_CANDIDATES` independent (block, tube) pairs and keeps the first that satisfies the
    separations; if none does (vanishingly rare with the default ranges), the options'
    `fallback_layout` positions with the first draw's yaws.
    """
    k_block, k_tube = jax.random.split(key)

    def draw(k: jax.Array, xr: Pair, yr: Pair, yawr: Pair) -> jax.Array:
        kx, ky, kyaw = jax.random.split(k, 3)
        u, n = jax.random.uniform, _CANDIDATES
        return jnp.stack(
            [
                u(kx, (n,), minval=xr[0], maxval=xr[1]),
                u(ky, (n,), minval=yr[0], maxval=yr[1]),
                u(kyaw, (n,), minval=yawr[0], maxval=yawr[1]),
            ],
            axis=1,
        )

    blocks = draw(k_block, o.block_spawn_x, o.block_spawn_y, o.block_spawn_yaw)
    tubes = draw(k_tube, o.tube_spawn_x, o.tube_spawn_y, o.tube_spawn_yaw)
    r_block, r_tube = o.block_radius, o.tube_diameter / 2
    ok = (
        (fo.norm(blocks[:, :2]) >= o.robot_keepout + r_block)
        & (fo.norm(tubes[:, :2]) >= o.robot_keepout + r_tube)
        & (fo.norm(blocks[:, :2] - tubes[:, :2]) >= r_block + r_tube + o.spawn_gap)
    )
    i = jnp.argmax(ok)
    fallback_block, fallback_tube = o.fallback_layout()
    block = jnp.where(ok[i], blocks[i], jnp.append(jnp.array(fallback_block), blocks[0, 2]))
    tube = jnp.where(ok[i], tubes[i], jnp.append(jnp.array(fallback_tube), tubes[0, 2]))
    return block, tube


def insertion(o: So101BoxOptions, q: Quantities) -> dict[str, jax.Array]:
    """The success predicate and its terms on one env's `Quantities`.

    `depth`: how far the tube's lower end is below the block's top face, along the block's
    axis (m); `hole_offset`: that end's distance from the hole's axis (m); `cos_tilt`: cosine
    of the tube axis' angle from vertical (either end down); `lower`: that end (world, m);
    `success`: all three within the options' tolerances.
    """
    end_a, end_b = q.site_pos[TUBE_END_A], q.site_pos[TUBE_END_B]
    lower = jnp.where(end_a[2] <= end_b[2], end_a, end_b)
    axis = end_b - end_a
    cos_tilt = jnp.abs(axis[2]) / jnp.maximum(fo.norm(axis), 1e-9)
    local = rotate_inverse(q.body_quat[BLOCK], lower - q.body_pos[BLOCK])
    depth = o.block_size[2] / 2 - local[2]
    hole_offset = fo.norm(local[:2])
    success = (
        (depth >= o.insertion_depth)
        & (hole_offset <= o.hole_diameter / 2)
        & (cos_tilt >= math.cos(o.tilt_tolerance))
    )
    return {
        "depth": depth,
        "hole_offset": hole_offset,
        "cos_tilt": cos_tilt,
        "lower": lower,
        "success": success,
    }


def reward(o: So101BoxOptions, q: Quantities, lower: jax.Array, success: jax.Array) -> jax.Array:
    """Dense reward: ``-0.5 |grasp - tube| - |lower end - hole axis at insertion depth| +
    1[success]``, with `lower` the tube's lower end from `insertion`."""
    tube_pos, block_pos, block_quat = q.body_pos[TUBE], q.body_pos[BLOCK], q.body_quat[BLOCK]
    target = block_pos + quat_axis_z(block_quat) * (o.block_size[2] / 2 - o.insertion_depth)
    return (
        -0.5 * fo.norm(q.site_pos[GRASP] - tube_pos)
        - fo.norm(lower - target)
        + success.astype(jnp.float32)
    )


def episode_factors(q: Quantities) -> dict[str, jax.Array]:
    """Randomised factors of the episode, from its reset state (for success breakdowns)."""
    tube, block = q.body_pos[TUBE][:2], q.body_pos[BLOCK][:2]
    quat = q.body_quat[BLOCK]
    return {
        "tube_block_distance": fo.norm(tube - block),
        "tube_reach": fo.norm(tube),
        "block_reach": fo.norm(block),
        "block_yaw": 2 * jnp.arctan2(quat[3], quat[0]),  # the block is only yawed at reset
    }
