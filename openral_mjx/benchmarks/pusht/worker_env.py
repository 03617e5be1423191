"""PushT as a gym-style env (runs in a worker of the ``gym-envs`` environment).

gym-pusht 0.1.8's `PushTEnv` (pymunk physics, pygame drawing), built as lerobot 0.4.4's PushT
env builds it (``gym_pusht/PushT-v0`` with ``obs_type`` and ``render_mode="rgb_array"``;
lerobot passes no observation size, so the image is gym-pusht's 96x96), without gymnasium's
checker wrappers. `reset(seed=s)` re-seeds the env's own generator (gymnasium's ``np_random``)
and rebuilds the pymunk space, so seed s gives the same initial agent and block placement
whatever this env ran before and whichever worker runs it.

Observation, lerobot's names: ``agent_pos`` (the agent's x, y in [0, 512]) and, per
``obs_type``, ``pixels`` (``pixels_agent_pos``: RGB uint8, ``image_size`` square, default 96)
or ``environment_state`` (``environment_state_agent_pos``: the T's 8 keypoints, 16 floats),
float32. Action: the agent's target position (x, y) in [0, 512], PD-tracked for 10 physics
substeps (10 Hz). Success: ``info["is_success"]`` (the T covers > 95% of the goal), which ends
the episode. Reset info carries the episode factors: the block's initial pose (x, y, angle)
and the agent's initial position, read from the env after its reset.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

FACTORS = ("block_x", "block_y", "block_angle", "agent_x", "agent_y")
OBS_TYPES = ("pixels_agent_pos", "environment_state_agent_pos")


class PushTEnv:
    """gym-pusht's PushT (see module docstring)."""

    def __init__(
        self, task: str = "PushT-v0", obs_type: str = "pixels_agent_pos", image_size: int = 96
    ) -> None:
        os.environ.setdefault("SDL_VIDEODRIVER", "dummy")  # pygame draws off screen only
        os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
        from gym_pusht.envs import PushTEnv as Env

        if task != "PushT-v0":
            raise ValueError(f"unknown PushT task {task!r}")
        if obs_type not in OBS_TYPES:
            raise ValueError(f"unknown PushT obs_type {obs_type!r}")
        self.env = Env(
            obs_type=obs_type,
            render_mode="rgb_array",
            observation_width=image_size,
            observation_height=image_size,
        )

    @staticmethod
    def _obs(raw: dict[str, Any]) -> dict[str, np.ndarray]:
        return {
            k: np.asarray(v) if k == "pixels" else np.asarray(v, np.float32) for k, v in raw.items()
        }

    def _factors(self) -> dict[str, float]:
        env = self.env
        block = (*env.block.position, env.block.angle)
        return dict(zip(FACTORS, map(float, (*block, *env.agent.position)), strict=True))

    def reset(self, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        del options
        raw, _ = self.env.reset(seed=None if seed is None else int(seed) % 2**32)
        return self._obs(raw), {"is_success": False, "factors": self._factors()}

    def step(self, action: np.ndarray) -> tuple[dict, float, bool, bool, dict]:
        a = np.clip(np.asarray(action, np.float64), 0.0, 512.0)
        raw, reward, terminated, truncated, info = self.env.step(a)
        success = bool(info["is_success"])
        return (
            self._obs(raw),
            float(reward),
            bool(terminated),
            bool(truncated),
            {"is_success": success},
        )

    def close(self) -> None:
        self.env.close()


def make(**kwargs: Any) -> PushTEnv:
    return PushTEnv(**kwargs)
