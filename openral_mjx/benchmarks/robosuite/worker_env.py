"""A robosuite task as a gym-style env (runs in a worker of the ``lerobot-libero`` environment).

robosuite 1.4 (the version LIBERO pins) with a Panda under operational-space control
(`OSC_POSE`: 6-D end-effector pose delta and a gripper command, all in [-1, 1]) at 20 Hz.
Observation: ``state`` = end-effector position (3), axis-angle (3) and gripper finger
positions (2); ``object`` = the task's object observation (for `Lift`: cube position,
quaternion and gripper-to-cube vector, 10 floats); with ``image_size > 0`` also ``image``, the
agent-view camera (RGB uint8, upright). robosuite samples object placements from numpy's global
RNG, so a reset seeds it from the episode's seed. Success: the task's own `_check_success`.
"""

from __future__ import annotations

from typing import Any

import numpy as np


def axis_angle(quat_xyzw: np.ndarray) -> np.ndarray:
    """Unit quaternion (x, y, z, w) -> axis * angle (robosuite's `quat2axisangle`)."""
    w = float(np.clip(quat_xyzw[3], -1.0, 1.0))
    s = np.sqrt(1.0 - w * w)
    if s < 1e-8:
        return np.zeros(3, np.float32)
    return (quat_xyzw[:3] * 2.0 * np.arccos(w) / s).astype(np.float32)


class RobosuiteEnv:
    """One robosuite task with a Panda (see module docstring)."""

    def __init__(self, task: str = "Lift", image_size: int = 0, horizon: int = 1000) -> None:
        import robosuite as suite

        controller = suite.load_controller_config(default_controller="OSC_POSE")
        self.image_size = image_size
        self.env = suite.make(
            task,
            robots="Panda",
            controller_configs=controller,
            has_renderer=False,
            has_offscreen_renderer=image_size > 0,
            use_camera_obs=image_size > 0,
            camera_names="agentview",
            camera_heights=max(image_size, 1),
            camera_widths=max(image_size, 1),
            control_freq=20,
            horizon=horizon,
            reward_shaping=True,
            ignore_done=True,
        )

    def _obs(self, raw: dict[str, Any]) -> dict[str, np.ndarray]:
        out = {
            "state": np.concatenate(
                [
                    raw["robot0_eef_pos"].astype(np.float32),
                    axis_angle(raw["robot0_eef_quat"]),
                    raw["robot0_gripper_qpos"].astype(np.float32),
                ]
            ),
            "object": raw["object-state"].astype(np.float32),
        }
        if self.image_size > 0:
            out["image"] = np.ascontiguousarray(raw["agentview_image"][::-1, ::-1])
        return out

    def reset(self, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        del options
        np.random.seed(None if seed is None else seed % 2**32)
        raw = self.env.reset()
        return self._obs(raw), {"is_success": False}

    def step(self, action: np.ndarray) -> tuple[dict, float, bool, bool, dict]:
        raw, reward, _, _ = self.env.step(np.asarray(action, np.float64))
        success = bool(self.env._check_success())
        return self._obs(raw), float(reward), success, False, {"is_success": success}

    def close(self) -> None:
        self.env.close()
