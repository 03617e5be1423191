"""An ALOHA task as a gym-style env (runs in a worker of the ``gym-envs`` environment).

gym-aloha 0.1.5's `AlohaEnv` (dm_control over MuJoCo 3.x: two ViperX 300 arms) for
``AlohaInsertion-v0`` (task ``insertion``: a peg and a socket) or ``AlohaTransferCube-v0``
(``transfer_cube``), built as lerobot 0.4.4 builds it (``obs_type="pixels_agent_pos"``,
``render_mode="rgb_array"``). gym-aloha's reset with seed s seeds the task's generator and
samples the objects' positions from ``RandomState(s)`` (`sample_box_pose`,
`sample_insertion_pose`), and dm_control's reset puts MuJoCo's data back to the model's
defaults first, so seed s gives the same initial state whatever this env ran before.

Observation, lerobot's names: ``top`` (the ``top`` camera, RGB uint8, ``image_height`` x
``image_width``, lerobot's 480 x 640 by default; 0 drops the camera) and ``agent_pos``
(14 float32: each arm's 6 joint positions and its normalised gripper opening). gym-aloha's task
renders three 480 x 640 cameras at every reset and step (``top``, ``angle``,
``front_close``) though its gym observation keeps only ``top``; this env renders ``top`` alone,
at the requested size, which leaves ``top`` and ``agent_pos`` as gym-aloha returns them and
saves two thirds of the rendering. Action: 14-D absolute joint targets (6 per arm) and
normalised gripper targets (0 closed, 1 open), 50 Hz. Success: ``info["is_success"]`` (the
task's top reward, 4: cube held by the left gripper in the air; peg inserted in the socket),
which ends the episode. A step whose physics blows up (dm_control's `PhysicsError`: non-finite
accelerations, e.g. under random joint targets over the whole range) ends the episode as
diverged (``info["diverged"]``) with its last observation. Reset info carries the episode
factors: the objects' initial x, y (gym-aloha fixes their height, 5 cm, and orientation).
"""

from __future__ import annotations

import collections
from typing import Any

import numpy as np

TASKS = {"AlohaInsertion-v0": "insertion", "AlohaTransferCube-v0": "transfer_cube"}
FACTORS = {
    "AlohaInsertion-v0": ("peg_x", "peg_y", "socket_x", "socket_y"),
    "AlohaTransferCube-v0": ("cube_x", "cube_y"),
}
# free joints' position offsets in qpos (after the arms' 16) of each object
OBJECTS = {
    "AlohaInsertion-v0": (("peg", 16), ("socket", 23)),
    "AlohaTransferCube-v0": (("cube", 16),),
}


class AlohaEnv:
    """One gym-aloha task (see module docstring)."""

    _last: dict[str, np.ndarray]

    def __init__(
        self, task: str = "AlohaInsertion-v0", image_height: int = 480, image_width: int = 640
    ) -> None:
        from gym_aloha.env import AlohaEnv as Env

        if task not in TASKS:
            raise ValueError(f"unknown ALOHA task {task!r}")
        self.task = task
        self.env = Env(task=TASKS[task], obs_type="pixels_agent_pos", render_mode="rgb_array")
        self.camera = image_height > 0 and image_width > 0
        inner = self.env._env.task
        size = {"height": image_height, "width": image_width, "camera_id": "top"}

        def get_observation(physics) -> collections.OrderedDict:
            obs = collections.OrderedDict()
            obs["qpos"] = inner.get_qpos(physics)
            obs["qvel"] = inner.get_qvel(physics)
            obs["env_state"] = inner.get_env_state(physics)
            obs["images"] = {"top": physics.render(**size) if self.camera else np.zeros(0)}
            return obs

        inner.get_observation = get_observation  # `top` only (see module docstring)

    def _obs(self, raw: dict[str, Any]) -> dict[str, np.ndarray]:
        out = {"agent_pos": np.asarray(raw["agent_pos"], np.float32)}
        if self.camera:
            out["top"] = np.asarray(raw["pixels"]["top"], np.uint8)
        return out

    def _factors(self) -> dict[str, float]:
        qpos = self.env._env.physics.data.qpos
        values = [float(qpos[at + i]) for _, at in OBJECTS[self.task] for i in (0, 1)]
        return dict(zip(FACTORS[self.task], values, strict=True))

    def reset(self, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        del options
        raw, _ = self.env.reset(seed=None if seed is None else int(seed) % 2**32)
        self._last = self._obs(raw)
        return self._last, {"is_success": False, "factors": self._factors()}

    def step(self, action: np.ndarray) -> tuple[dict, float, bool, bool, dict]:
        from dm_control.rl.control import PhysicsError

        try:
            raw, reward, terminated, truncated, info = self.env.step(np.asarray(action, np.float64))
        except PhysicsError:  # non-finite accelerations: the episode ends as diverged
            return self._last, 0.0, True, False, {"is_success": False, "diverged": True}
        self._last = self._obs(raw)
        success = bool(info["is_success"])
        return self._last, float(reward), bool(terminated), bool(truncated), {"is_success": success}

    def close(self) -> None:
        self.env.close()


def make(**kwargs: Any) -> AlohaEnv:
    return AlohaEnv(**kwargs)
