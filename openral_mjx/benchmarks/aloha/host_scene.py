"""`aloha`: gym-aloha's bimanual ALOHA tasks (dm_control, MuJoCo 3.x on the CPU) through the
host adapter.

Task: ``AlohaInsertion-v0`` (lerobot's default: pick up the peg and the socket, insert one in
the other) or ``AlohaTransferCube-v0`` (the right arm picks up the cube and hands it to the
left). Seed s seeds gym-aloha's own randomisation of the objects' positions (its
``RandomState(seed)`` samplers) with a value drawn from the episode's reset key, so seed s has
the same initial state on every run and batch size. Observation, lerobot 0.4.4's ALOHA
conventions: ``top`` (the top camera, upright RGB uint8, ``image_height`` x ``image_width``,
lerobot's 480 x 640 by default; a policy trained at another size takes that size, and 0 drops
the camera) and ``agent_pos`` (14 float32: per arm 6 joint positions and the normalised
gripper opening), so a lerobot policy maps ``observation.images.top`` <- ``top`` and
``observation.state`` <- ``agent_pos``. Action: 14-D absolute joint targets and normalised
gripper targets (0 closed, 1 open), clipped to the arms' actuator ranges and [0, 1] (MuJoCo
clamps to the same ranges), 50 Hz. Success: gym-aloha's ``info["is_success"]`` (the task's
top reward), which ends the episode; episodes last at most lerobot's 400 steps by default.
Episode factors: the objects' initial x, y (``cube_*``; ``peg_*`` and ``socket_*``). Runs in
the ``gym-envs`` worker environment, created on first use (see `openral_mjx.host.envs`);
the camera renders offscreen through EGL (``gl=osmesa`` where EGL is missing).
"""

from __future__ import annotations

import dataclasses

from openral_mjx.core.errors import unknown
from openral_mjx.core.options import check
from openral_mjx.host.envs import ensure_env
from openral_mjx.scenes import SceneEntry
from openral_mjx.scenes.host_scene import HostOptions, HostScene, HostSceneSpec

ENV = "gym-envs"
ROBOT = "aloha"
FACTORY = "openral_mjx.benchmarks.aloha.worker_env:make"
TASKS = ("AlohaInsertion-v0", "AlohaTransferCube-v0")
# Instructions (ours: lerobot's ALOHA env hands policies gym-aloha's task id, e.g. "insertion").
INSTRUCTIONS = {
    "AlohaInsertion-v0": "insert the peg into the socket",
    "AlohaTransferCube-v0": "pick up the cube with the right arm and hand it to the left arm",
}
FACTORS = {
    "AlohaInsertion-v0": ("peg_x", "peg_y", "socket_x", "socket_y"),
    "AlohaTransferCube-v0": ("cube_x", "cube_y"),
}
MAX_STEPS = 400  # lerobot's ALOHA episode length
CONTROL_DT = 0.02  # gym-aloha's 50 Hz
# Per arm: the position actuators' ctrlrange of waist, shoulder, elbow, forearm roll, wrist
# angle and wrist rotate (gym-aloha's MJCF), then the normalised gripper target.
ARM_LOW = (-3.14158, -1.85005, -1.76278, -3.14158, -1.8675, -3.14158, 0.0)
ARM_HIGH = (3.14158, 1.25664, 1.6057, 3.14158, 2.23402, 3.14158, 1.0)
ACTION_SIZE = 14
SUITES = {"all": TASKS}


def suite_tasks(suite: str) -> list[str]:
    """The tasks of `suite` (``all``: both ALOHA tasks, insertion first)."""
    if suite not in SUITES:
        raise unknown("ALOHA suite", suite, SUITES)
    return list(SUITES[suite])


@dataclasses.dataclass(frozen=True)
class AlohaOptions(HostOptions):
    """`aloha` options: the task, the top camera's size (lerobot's 480 x 640; 0 x 0: no
    camera), the episode limit and the offscreen GL platform (`egl`, or `osmesa`)."""

    task: str = "AlohaInsertion-v0"
    image_height: int = 480
    image_width: int = 640
    max_steps: int = MAX_STEPS
    gl: str = "egl"

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.task not in TASKS:
            raise unknown("ALOHA task", self.task, TASKS)
        size = (self.image_height, self.image_width)
        check(
            min(size) >= 1 or size == (0, 0),
            f"option image_height={size[0]}, image_width={size[1]}: both >= 1, or both 0 "
            "(no camera)",
        )
        check(self.max_steps >= 1, f"option max_steps={self.max_steps}: must be >= 1")
        check(self.gl in ("egl", "osmesa"), f"option gl={self.gl!r}; valid: egl, osmesa")


def aloha(options: AlohaOptions, **_: object) -> HostScene:
    o = options
    observation: dict = {"agent_pos": ((ACTION_SIZE,), "float32")}
    if o.image_height > 0:
        observation["top"] = ((o.image_height, o.image_width, 3), "uint8")
    kwargs = {"task": o.task, "image_height": o.image_height, "image_width": o.image_width}
    env = {"MUJOCO_GL": o.gl, "PYOPENGL_PLATFORM": o.gl}  # dm_control reads it on import
    batch = dataclasses.replace(
        o.batch_config(FACTORY, kwargs, observation, ACTION_SIZE, env), factors=FACTORS[o.task]
    )
    spec = HostSceneSpec(
        name="aloha",
        task=o.task,
        robot=ROBOT,
        batch=batch,
        action_low=ARM_LOW * 2,
        action_high=ARM_HIGH * 2,
        control_dt=CONTROL_DT,
        max_steps=o.max_steps,
        instruction=INSTRUCTIONS[o.task],
    )
    return HostScene(spec, o, ENV, ensure_env(ENV))


# `SCENES`'s entry for `aloha` (registered by reference in `openral_mjx.scenes`)
SCENE = SceneEntry(
    AlohaOptions,
    aloha,
    ROBOT,
    backends=("host",),
    suites=suite_tasks,
    worker_env=ENV,
    tasks=", ".join(TASKS),
    suite_names=tuple(SUITES),
)
