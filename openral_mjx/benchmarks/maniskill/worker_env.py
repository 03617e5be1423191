"""A ManiSkill3 table-top task as a gym-style env (runs in a worker of the ``maniskill``
environment).

ManiSkill 3.0.1's ``PickCube-v1``, ``PushCube-v1`` or ``StackCube-v1`` (a Franka Panda on a
table, SAPIEN 3.0.3's PhysX on the CPU: ``sim_backend="cpu"``, one env per instance), with
``obs_mode="state"`` and no renderer (``render_backend="none"``, ``render_mode=None``), built
from ManiSkill's registry entry without gymnasium's wrappers (the evaluator owns the episode
limit; ManiSkill registers 50 steps for all three).

No renderer: SAPIEN 3.0.3 builds ``RenderMaterial`` (and ``RenderTexture2D``) objects while it
loads the robot's URDF and ManiSkill's actors even with ``render_backend="none"``, and their
constructor needs a Vulkan device ("failed to find a rendering device" on a machine without
one; Mesa's CPU Vulkan, lavapipe, lacks ``VK_KHR_external_semaphore_fd`` before Mesa 24.3).
ManiSkill itself adds no render component to a scene that cannot render, so those materials are
never used: `_without_render_materials` swaps both classes for an inert stand-in before
ManiSkill is imported, on every machine alike (physics and state observations do not depend on
visuals), and nothing touches Vulkan.

Seed s reaches ManiSkill's ``reset(seed=s)``, which seeds its episode RNG and runs the task's
initialisation under ``torch.manual_seed(s)``, so seed s gives the same initial state whatever
this env ran before. With ``fresh`` (the default) the whole episode replays bit for bit: every
reset rebuilds the SAPIEN scene (ManiSkill's ``reconfigure``, ~0.2 s here, about 30 steps).
PhysX keeps state across ManiSkill's plain resets: an episode replayed in an env that already
ran one leaves the fresh env's trajectory, by float rounding, at the first contact (measured:
a scripted PushCube push, step 9).

Observation: ``state`` (ManiSkill's flat state vector, float32: joint positions and
velocities, TCP pose, goal and object poses; 42 / 35 / 48 values). Action: the Panda's
controller in ``control_mode`` (``pd_joint_delta_pos``, ManiSkill's default: 7 joint deltas
and the gripper; ``pd_ee_delta_pos``: 3 + gripper; ``pd_ee_delta_pose``: 6 + gripper),
normalised to [-1, 1], 20 Hz (100 Hz physics). Success: ``info["success"]``, which ends the
episode. Reset info carries the episode factors: the objects' (and PickCube's goal's) initial
positions, read from the env after its reset.
"""

from __future__ import annotations

import sys
from typing import Any

import numpy as np

TASKS = ("PickCube-v1", "PushCube-v1", "StackCube-v1")
CONTROL_MODES = {"pd_joint_delta_pos": 8, "pd_ee_delta_pos": 4, "pd_ee_delta_pose": 7}
STATE_SIZE = {"PickCube-v1": 42, "PushCube-v1": 35, "StackCube-v1": 48}
# factor -> (the env's actor attribute, coordinate)
FACTORS = {
    "PickCube-v1": {
        "cube_x": ("cube", 0),
        "cube_y": ("cube", 1),
        "goal_x": ("goal_site", 0),
        "goal_y": ("goal_site", 1),
        "goal_z": ("goal_site", 2),
    },
    "PushCube-v1": {"cube_x": ("obj", 0), "cube_y": ("obj", 1)},
    "StackCube-v1": {
        "cubeA_x": ("cubeA", 0),
        "cubeA_y": ("cubeA", 1),
        "cubeB_x": ("cubeB", 0),
        "cubeB_y": ("cubeB", 1),
    },
}


class _InertRenderObject:
    """Stands in for SAPIEN's render materials and textures where nothing renders: takes any
    arguments and attributes, and any method call does nothing."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self.__dict__.update(kwargs)

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__"):
            raise AttributeError(name)
        return lambda *args, **kwargs: None


_ORIGINAL: dict[str, type] = {}
_INERT: dict[str, type] = {}


def _without_render_materials() -> None:
    """Swap SAPIEN's ``RenderMaterial`` and ``RenderTexture2D`` for inert stand-ins, in
    ``sapien.render`` and in every loaded module that imported them by name (see module
    docstring). Call before importing ManiSkill and again after (idempotent)."""
    import sapien.render

    for name in ("RenderMaterial", "RenderTexture2D"):
        if name not in _ORIGINAL:
            _ORIGINAL[name] = getattr(sapien.render, name)
            _INERT[name] = type(name, (_InertRenderObject,), {})
        for module in list(sys.modules.values()):
            found = getattr(module, "__dict__", {}).get(name)  # no module __getattr__ hooks
            if found is _ORIGINAL[name]:
                setattr(module, name, _INERT[name])


class ManiSkillEnv:
    """One ManiSkill3 task on the CPU, state observations, no renderer (module docstring)."""

    def __init__(
        self,
        task: str = "PickCube-v1",
        control_mode: str = "pd_joint_delta_pos",
        fresh: bool = True,
    ) -> None:
        if task not in TASKS:
            raise ValueError(f"unknown ManiSkill task {task!r}")
        if control_mode not in CONTROL_MODES:
            raise ValueError(f"unknown ManiSkill control_mode {control_mode!r}")
        import torch

        torch.set_num_threads(1)  # one env per worker process: parallelism is across workers
        _without_render_materials()
        import mani_skill.envs  # noqa: F401  (registers the tasks)
        from mani_skill.utils.registration import REGISTERED_ENVS

        _without_render_materials()  # modules that imported the classes meanwhile
        self.task, self.fresh = task, fresh
        self.env = REGISTERED_ENVS[task].make(
            obs_mode="state",
            control_mode=control_mode,
            render_mode=None,
            sim_backend="cpu",
            render_backend="none",
            num_envs=1,
        )

    @staticmethod
    def _obs(raw: Any) -> dict[str, np.ndarray]:
        return {"state": np.asarray(raw[0], np.float32)}

    def _factors(self) -> dict[str, float]:
        env = self.env
        return {
            name: float(getattr(env, actor).pose.p[0, i])
            for name, (actor, i) in FACTORS[self.task].items()
        }

    def reset(self, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        del options
        raw, _ = self.env.reset(
            seed=None if seed is None else int(seed) % 2**32, options={"reconfigure": self.fresh}
        )
        return self._obs(raw), {"is_success": False, "factors": self._factors()}

    def step(self, action: np.ndarray) -> tuple[dict, float, bool, bool, dict]:
        a = np.clip(np.asarray(action, np.float32), -1.0, 1.0)
        raw, reward, terminated, truncated, info = self.env.step(a)
        success = bool(info["success"][0])
        return (
            self._obs(raw),
            float(reward[0]),
            bool(terminated[0]),
            bool(truncated[0]),
            {"is_success": success},
        )

    def close(self) -> None:
        self.env.close()


def make(**kwargs: Any) -> ManiSkillEnv:
    return ManiSkillEnv(**kwargs)
