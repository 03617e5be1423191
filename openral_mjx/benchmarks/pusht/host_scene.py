"""`pusht`: gym-pusht's PushT (2-D pymunk physics on the CPU) through the host adapter.

Task: ``PushT-v0`` (the only one): push the T-shaped block onto the goal pose with a round
agent. Seed s seeds gym-pusht's own randomisation of the agent position and the block's pose
(its ``np_random``, re-seeded at every reset) with a value drawn from the episode's reset key,
so seed s has the same initial state on every run and batch size. Observation, lerobot 0.4.4's
PushT conventions: ``agent_pos`` (2 float32) and, with ``obs_type=pixels_agent_pos``
(lerobot's default), ``pixels`` (RGB uint8, ``image_size`` square, 96 as lerobot's PushT env
renders it), or with ``obs_type=environment_state_agent_pos`` ``environment_state`` (the T's 8
keypoints, 16 float32). Action: the agent's target position (x, y) in [0, 512], 10 Hz.
Success: gym-pusht's ``info["is_success"]`` (coverage of the goal > 95%), which ends the
episode; episodes last at most lerobot's 300 steps by default. Episode factors: the block's
initial pose (``block_x``, ``block_y``, ``block_angle``) and the agent's initial position
(``agent_x``, ``agent_y``). Runs in the ``gym-envs`` worker environment, created on first use
(see `openral_mjx.host.envs`).
"""

from __future__ import annotations

import dataclasses

from openral_mjx.core.errors import unknown
from openral_mjx.core.options import check
from openral_mjx.host.envs import ensure_env
from openral_mjx.scenes import SceneEntry
from openral_mjx.scenes.host_scene import HostOptions, HostScene, HostSceneSpec

ENV = "gym-envs"
ROBOT = "pusht_agent"
FACTORY = "openral_mjx.benchmarks.pusht.worker_env:make"
FACTORS = ("block_x", "block_y", "block_angle", "agent_x", "agent_y")
TASKS = ("PushT-v0",)
# Instructions (ours: lerobot's PushT env hands policies an empty `task`).
INSTRUCTIONS = {"PushT-v0": "push the T-shaped block onto the T-shaped target"}
OBS_TYPES = ("pixels_agent_pos", "environment_state_agent_pos")
MAX_STEPS = 300  # lerobot's PushT episode length (and gym-pusht's registered limit)
CONTROL_DT = 0.1  # 10 Hz: 10 pymunk substeps of 10 ms
ACTION_HIGH = 512.0  # the agent's target position, in gym-pusht's pixels of its 512 x 512 table


@dataclasses.dataclass(frozen=True)
class PushTOptions(HostOptions):
    """`pusht` options: the task, lerobot's observation type (`pixels_agent_pos`: image and
    agent position; `environment_state_agent_pos`: keypoints and agent position), the image's
    side (lerobot's PushT policies see 96) and the episode limit."""

    task: str = "PushT-v0"
    obs_type: str = "pixels_agent_pos"
    image_size: int = 96
    max_steps: int = MAX_STEPS

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.task not in TASKS:
            raise unknown("PushT task", self.task, TASKS)
        if self.obs_type not in OBS_TYPES:
            raise unknown("PushT obs_type", self.obs_type, OBS_TYPES)
        check(self.image_size >= 1, f"option image_size={self.image_size}: must be >= 1")
        check(self.max_steps >= 1, f"option max_steps={self.max_steps}: must be >= 1")


def pusht(options: PushTOptions, **_: object) -> HostScene:
    o = options
    observation: dict = {"agent_pos": ((2,), "float32")}
    if o.obs_type == "pixels_agent_pos":
        observation["pixels"] = ((o.image_size, o.image_size, 3), "uint8")
    else:
        observation["environment_state"] = ((16,), "float32")
    kwargs = {"task": o.task, "obs_type": o.obs_type, "image_size": o.image_size}
    env = {"SDL_VIDEODRIVER": "dummy", "PYGAME_HIDE_SUPPORT_PROMPT": "1"}
    batch = dataclasses.replace(
        o.batch_config(FACTORY, kwargs, observation, 2, env), factors=FACTORS
    )
    spec = HostSceneSpec(
        name="pusht",
        task=o.task,
        robot=ROBOT,
        batch=batch,
        action_low=(0.0, 0.0),
        action_high=(ACTION_HIGH, ACTION_HIGH),
        control_dt=CONTROL_DT,
        max_steps=o.max_steps,
        instruction=INSTRUCTIONS[o.task],
    )
    return HostScene(spec, o, ENV, ensure_env(ENV))


# `SCENES`'s entry for `pusht` (registered by reference in `openral_mjx.scenes`)
SCENE = SceneEntry(
    PushTOptions, pusht, ROBOT, backends=("host",), worker_env=ENV, tasks=", ".join(TASKS)
)
