"""`tabletop_push` task logic: reset sampling, the success predicate, reward, episode factors.

Pure JAX functions of the options, one env's physics `Quantities`, the episode's goal and a
PRNG key, with no backend in sight, so one definition runs on every physics backend. They read
the quantities `quantity_spec` declares, by the row indices below.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from openral_mjx.core import fixed_order as fo
from openral_mjx.physics import Quantities, QuantitySpec
from openral_mjx.physics.cameras import SensorSpec
from openral_mjx.scenes.tabletop_push.options import TabletopPushOptions

# Rows of `Quantities.body_pos`/`body_quat` and of `Quantities.site_pos` (see `quantity_spec`).
CUBE = 0
EE = 0


def quantity_spec(ee_site: str, sensors: tuple[SensorSpec, ...]) -> QuantitySpec:
    """What the task and the observation read: the cube's pose, the end-effector site, the
    observed sensors."""
    return QuantitySpec(bodies=("cube",), sites=(ee_site,), sensors=sensors)


def cube_rest_z(o: TabletopPushOptions) -> float:
    """Height of the cube's centre resting on the table (world z, m)."""
    return o.table_height + o.cube_size / 2


def sample_episode(o: TabletopPushOptions, key: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Cube (x, y, yaw) and goal (x, y) for one episode.

    The goal lies at a random bearing and a distance in `goal_distance` from the cube; a goal
    outside the goal region takes the opposite bearing, and is then clamped into the region.
    """
    kx, ky, kyaw, kth, kr = jax.random.split(key, 5)
    u = jax.random.uniform
    cube_xy = jnp.stack(
        [
            u(kx, (), minval=o.cube_spawn_x[0], maxval=o.cube_spawn_x[1]),
            u(ky, (), minval=o.cube_spawn_y[0], maxval=o.cube_spawn_y[1]),
        ]
    )
    yaw = u(kyaw, (), minval=-jnp.pi, maxval=jnp.pi)
    theta = u(kth, (), minval=-jnp.pi, maxval=jnp.pi)
    dist = u(kr, (), minval=o.goal_distance[0], maxval=o.goal_distance[1])
    # Computed once: the goal feeds both `info` and the observation, and XLA recomputed
    # this product inside both fusions, rounding differently at some batch sizes (the
    # goal in the observation then differed in the last bit from one batch size to another).
    offset = jax.lax.optimization_barrier(dist * jnp.stack([jnp.cos(theta), jnp.sin(theta)]))
    lo = jnp.array([o.goal_region_x[0], o.goal_region_y[0]])
    hi = jnp.array([o.goal_region_x[1], o.goal_region_y[1]])
    inside = jnp.all((cube_xy + offset >= lo) & (cube_xy + offset <= hi))
    # Flip the bearing when it leaves the goal region, then clamp what still does.
    goal_xy = jnp.clip(jnp.where(inside, cube_xy + offset, cube_xy - offset), lo, hi)
    return jnp.concatenate([cube_xy, yaw[None]]), goal_xy


def success(
    o: TabletopPushOptions, q: Quantities, goal_xy: jax.Array, cube_dof_adr: int
) -> dict[str, jax.Array]:
    """The success predicate and its terms on one env's `Quantities`.

    `goal_dist`: cube centre to goal in the table plane (m); `resting`: the cube's centre
    within `rest_height_tol` of its resting height and its speed (from its free joint's
    linear velocity at `cube_dof_adr`) below `rest_speed`; `success`: both, near the goal.
    """
    cube_pos = q.body_pos[CUBE]
    goal_dist = fo.norm(cube_pos[:2] - goal_xy)
    cube_speed = fo.norm(q.qvel[cube_dof_adr : cube_dof_adr + 3])
    resting = (jnp.abs(cube_pos[2] - cube_rest_z(o)) <= o.rest_height_tol) & (
        cube_speed <= o.rest_speed
    )
    return {
        "goal_dist": goal_dist,
        "resting": resting,
        "success": (goal_dist <= o.goal_radius) & resting,
    }


def reward(q: Quantities, goal_dist: jax.Array, success: jax.Array) -> jax.Array:
    """Dense reward: ``-|cube_xy - goal_xy| - 0.5 |ee - cube| + 1[success]``."""
    return (
        -goal_dist - 0.5 * fo.norm(q.site_pos[EE] - q.body_pos[CUBE]) + success.astype(jnp.float32)
    )


def episode_factors(q: Quantities, goal_xy: jax.Array) -> dict[str, jax.Array]:
    """Randomised factors of the episode, from its reset state (for success breakdowns)."""
    cube_xy, quat = q.body_pos[CUBE][:2], q.body_quat[CUBE]
    to_goal = goal_xy - cube_xy
    yaw = 2 * jnp.arctan2(quat[3], quat[0])  # the cube is only ever yawed at reset
    quarter = jnp.pi / 2
    offset = jnp.mod(jnp.arctan2(to_goal[1], to_goal[0]) - yaw, quarter)
    return {
        "goal_distance": jnp.hypot(to_goal[0], to_goal[1]),
        "cube_x": cube_xy[0],
        "cube_y": cube_xy[1],
        "push_face_angle": jnp.minimum(offset, quarter - offset),
    }
