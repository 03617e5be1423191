"""`maniskill`: ManiSkill3's table-top tasks (SAPIEN's PhysX on the CPU, state observations)
through the host adapter.

Task: ``PickCube-v1`` (pick up the cube and hold it at the goal position), ``PushCube-v1``
(push the cube into the goal region in front of it) or ``StackCube-v1`` (stack the red cube on
the green one), each with ManiSkill 3.0.1's Franka Panda, ``sim_backend="cpu"``, one env per
worker slot and no renderer. Seed s seeds ManiSkill's own randomisation (its episode RNG and
``torch.manual_seed`` around the task's initialisation) with a value drawn from the episode's
reset key, so seed s has the same initial state on every run and batch size and, with
``fresh`` (the default: the scene rebuilt at every reset), the same episode bit for bit.
Observation:
``state`` (ManiSkill's ``obs_mode="state"`` vector: joint positions and velocities, TCP pose,
goal and object poses; float32, 42 / 35 / 48 values). Action: the Panda's controller in
``control_mode`` (ManiSkill's default ``pd_joint_delta_pos``: 8 values, 7 joint deltas and the
gripper; ``pd_ee_delta_pos``: 4; ``pd_ee_delta_pose``: 7), normalised to [-1, 1], 20 Hz.
Success: ManiSkill's ``info["success"]``, which ends the episode; episodes last at most
ManiSkill's registered 50 steps by default. Episode factors: the objects' initial x, y
(``cube_*``; ``cubeA_*``, ``cubeB_*``) and PickCube's goal position (``goal_x/y/z``). Runs in the
``maniskill`` worker environment, created on first use (see `openral_mjx.host.envs`). No
camera observations: SAPIEN renders through Vulkan only (see `worker_env`).
"""

from __future__ import annotations

import dataclasses

from openral_mjx.core.errors import unknown
from openral_mjx.core.options import check
from openral_mjx.host.envs import ensure_env
from openral_mjx.scenes import SceneEntry
from openral_mjx.scenes.host_scene import HostOptions, HostScene, HostSceneSpec

ENV = "maniskill"
ROBOT = "panda"  # ManiSkill's Franka Panda
FACTORY = "openral_mjx.benchmarks.maniskill.worker_env:make"
TASKS = ("PickCube-v1", "PushCube-v1", "StackCube-v1")
# Instructions (ours: ManiSkill's tasks carry none).
INSTRUCTIONS = {
    "PickCube-v1": "pick up the cube and move it to the goal position",
    "PushCube-v1": "push the cube into the goal region",
    "StackCube-v1": "stack the red cube on top of the green cube",
}
STATE_SIZE = {"PickCube-v1": 42, "PushCube-v1": 35, "StackCube-v1": 48}
FACTORS = {
    "PickCube-v1": ("cube_x", "cube_y", "goal_x", "goal_y", "goal_z"),
    "PushCube-v1": ("cube_x", "cube_y"),
    "StackCube-v1": ("cubeA_x", "cubeA_y", "cubeB_x", "cubeB_y"),
}
CONTROL_MODES = {"pd_joint_delta_pos": 8, "pd_ee_delta_pos": 4, "pd_ee_delta_pose": 7}
MAX_STEPS = 50  # ManiSkill's registered max_episode_steps of all three tasks
CONTROL_DT = 0.05  # 20 Hz control, 100 Hz physics


@dataclasses.dataclass(frozen=True)
class ManiSkillOptions(HostOptions):
    """`maniskill` options: the task, the Panda's controller (`pd_joint_delta_pos`,
    `pd_ee_delta_pos`, `pd_ee_delta_pose`; actions normalised to [-1, 1]), the episode limit,
    and whether every reset rebuilds the SAPIEN scene (`fresh`: seed s replays bit for bit
    whatever the env ran before; False: resets ~0.2 s faster, and episodes after the first
    in an env leave the fresh trajectory by float rounding once contacts begin)."""

    task: str = "PickCube-v1"
    control_mode: str = "pd_joint_delta_pos"
    max_steps: int = MAX_STEPS
    fresh: bool = True

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.task not in TASKS:
            raise unknown("ManiSkill task", self.task, TASKS)
        if self.control_mode not in CONTROL_MODES:
            raise unknown("ManiSkill control_mode", self.control_mode, CONTROL_MODES)
        check(self.max_steps >= 1, f"option max_steps={self.max_steps}: must be >= 1")


def maniskill(options: ManiSkillOptions, **_: object) -> HostScene:
    o = options
    observation = {"state": ((STATE_SIZE[o.task],), "float32")}
    kwargs = {"task": o.task, "control_mode": o.control_mode, "fresh": o.fresh}
    size = CONTROL_MODES[o.control_mode]
    env = {"OMP_NUM_THREADS": "1"}  # one env per worker process: no thread pools per worker
    batch = dataclasses.replace(
        o.batch_config(FACTORY, kwargs, observation, size, env), factors=FACTORS[o.task]
    )
    spec = HostSceneSpec(
        name="maniskill",
        task=o.task,
        robot=ROBOT,
        batch=batch,
        action_low=(-1.0,) * size,
        action_high=(1.0,) * size,
        control_dt=CONTROL_DT,
        max_steps=o.max_steps,
        instruction=INSTRUCTIONS[o.task],
    )
    return HostScene(spec, o, ENV, ensure_env(ENV))


# `SCENES`'s entry for `maniskill` (registered by reference in `openral_mjx.scenes`)
SCENE = SceneEntry(
    ManiSkillOptions, maniskill, ROBOT, backends=("host",), worker_env=ENV, tasks=", ".join(TASKS)
)
