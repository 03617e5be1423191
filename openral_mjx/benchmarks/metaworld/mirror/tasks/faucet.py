"""faucet-open-v3, faucet-close-v3: turn the faucet's handle (MetaWorld 3.1.1).

Both move ``faucetBase`` to the drawn position and aim at it + (+-0.175, 0, 0.125) (open: +,
close: -); the handle's joint is left as the hand reset leaves it. Observed object: the
``handleStartOpen`` (open) or ``handleStartClose`` (close) site + (0, 0, -0.01) and the
``faucetBase`` body's ``xquat`` (w-x-y-z); the goal is clipped to the hand box (their goal
space). Success: within 0.07 of the goal, for faucet-open measured from the observed handle
+ (-0.04, 0, 0.03).

Reward (MetaWorld's v2, both): 2 x (2 x the tcp's reach to that point (gaussian, within 1 cm)
+ 3 x its approach to the goal (long tail, within 0.07)); 10 on success.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp

from openral_mjx.benchmarks.metaworld.mirror.task import (
    ModelFacts,
    MovedBodyTask,
    View,
    tolerance,
)

HANDLE_LENGTH = 0.175


class _Faucet(MovedBodyTask):
    xml = "sawyer_xyz/sawyer_faucet.xml"
    hand_init_pos = (0.0, 0.4, 0.2)
    goal_low = (-0.5, 0.40, -0.15)
    goal_high = (0.5, 1.0, 0.5)
    hand_low = (-0.5, 0.40, -0.15)
    hand_high = (0.5, 1.0, 0.5)
    bodies = ("faucetBase",)
    moved_bodies = ("faucetBase",)
    handle_site: str
    side: float  # +1 open, -1 close
    obs_offset: tuple[float, float, float]

    def episode(self, facts: ModelFacts, vec: jax.Array, view: View) -> dict[str, jax.Array]:
        offset = jnp.array([self.side * HANDLE_LENGTH, 0.0, 0.125], vec.dtype)
        return {"target_pos": vec + offset, "obj_init_pos": vec}

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        handle = view.site_pos(self.handle_site) + jnp.array([0.0, 0.0, -0.01], jnp.float32)
        return handle, view.body_quat("faucetBase")

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        obj = obs[4:7] + jnp.asarray(self.obs_offset, obs.dtype)
        return jnp.linalg.norm(obj - episode["target_pos"]) <= 0.07

    has_reward = True

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        obj, target = obs[4:7] + jnp.asarray(self.obs_offset, obs.dtype), episode["target_pos"]
        start = episode["obj_init_pos"]
        to_target = jnp.linalg.norm(obj - target)
        in_place = tolerance(to_target, 0.07, jnp.abs(jnp.linalg.norm(start - target) - 0.07))
        tcp_to_obj = jnp.linalg.norm(obj - view.tcp_center)
        margin = jnp.abs(jnp.linalg.norm(start - episode["init_tcp"]) - 0.01)
        reach = tolerance(tcp_to_obj, 0.01, margin, "gaussian")
        return jnp.where(to_target <= 0.07, 10.0, 2.0 * (2.0 * reach + 3.0 * in_place))


class FaucetOpen(_Faucet):
    name = "faucet-open-v3"
    reset_low = (-0.05, 0.8, 0.0)
    reset_high = (0.05, 0.85, 0.0)
    sites = ("handleStartOpen",)
    handle_site = "handleStartOpen"
    side = 1.0
    obs_offset = (-0.04, 0.0, 0.03)


class FaucetClose(_Faucet):
    name = "faucet-close-v3"
    reset_low = (-0.1, 0.8, 0.0)
    reset_high = (0.1, 0.85, 0.0)
    sites = ("handleStartClose",)
    handle_site = "handleStartClose"
    side = -1.0
    obs_offset = (0.0, 0.0, 0.0)


TASKS = (FaucetOpen(), FaucetClose())
