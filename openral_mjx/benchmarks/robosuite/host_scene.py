"""`robosuite`: robosuite tasks with a Panda under OSC control, through the host adapter.

Task `Lift` (lift the cube above the table). Observation: ``state`` (end-effector position,
axis-angle, gripper fingers: 8 floats), ``object`` (cube position, quaternion, gripper-to-cube
vector: 10 floats), and with `image_size` > 0 the agent-view camera ``image``. Action: 6-D OSC
pose delta and gripper in [-1, 1] at 20 Hz. Seed s seeds robosuite's placement sampler (from
the episode's reset key). Runs robosuite 1.4 (the version LIBERO pins; robosuite 1.5 does not
build `Lift` on mujoco 4) in the ``lerobot-libero`` worker environment.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from openral_mjx.core.errors import unknown
from openral_mjx.core.options import check
from openral_mjx.host.envs import ensure_env
from openral_mjx.scenes import SceneEntry
from openral_mjx.scenes.host_scene import HostOptions, HostScene, HostSceneSpec

ENV = "lerobot-libero"
ROBOT = "panda"  # robosuite's Panda, also LIBERO's
OBJECT_SIZE = {"Lift": 10}  # the task's object observation
# Instructions (ours: robosuite and lerobot define none for these tasks).
INSTRUCTIONS = {"Lift": "lift the red cube off the table"}
CONTROL_DT = 0.05  # robosuite's and LIBERO's 20 Hz control


@dataclasses.dataclass(frozen=True)
class RobosuiteOptions(HostOptions):
    """`robosuite` options: the task, camera resolution (0: no camera) and episode limit."""

    task: str = "Lift"
    image_size: int = 0
    max_steps: int = 200
    gl: str = "egl"

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.task not in OBJECT_SIZE:
            raise unknown("robosuite task", self.task, OBJECT_SIZE)
        check(self.image_size >= 0, f"option image_size={self.image_size}: must be >= 0")
        check(self.max_steps >= 1, f"option max_steps={self.max_steps}: must be >= 1")
        check(self.gl in ("egl", "osmesa"), f"option gl={self.gl!r}; valid: egl, osmesa")


def panda_osc_scene(
    name: str,
    task: str,
    options: HostOptions,
    factory: str,
    kwargs: dict[str, Any],
    observation: dict[str, tuple[tuple[int, ...], str]],
    max_steps: int,
    gl: str,
    n_init_states: int = 0,
    instruction: str = "",
    reset_options: dict[str, Any] | None = None,
    flat_obs: bool = False,
) -> HostScene:
    """A robosuite-based scene (robosuite itself, or LIBERO on it): a Panda under OSC_POSE
    (7-D action in [-1, 1], 20 Hz) in the `lerobot-libero` worker environment."""
    batch = options.batch_config(
        factory, kwargs, observation, 7, {"MUJOCO_GL": gl, "PYOPENGL_PLATFORM": gl}
    )
    spec = HostSceneSpec(
        name=name,
        task=task,
        robot=ROBOT,
        batch=batch,
        action_low=(-1.0,) * 7,
        action_high=(1.0,) * 7,
        control_dt=CONTROL_DT,
        max_steps=max_steps,
        n_init_states=n_init_states,
        reset_options=dict(reset_options or {}),
        instruction=instruction,
        flat_obs=flat_obs,
    )
    return HostScene(spec, options, ENV, ensure_env(ENV))


def robosuite(options: RobosuiteOptions, **_: object) -> HostScene:
    o = options
    observation: dict = {"state": ((8,), "float32"), "object": ((OBJECT_SIZE[o.task],), "float32")}
    if o.image_size > 0:
        observation["image"] = ((o.image_size, o.image_size, 3), "uint8")
    kwargs = {"task": o.task, "image_size": o.image_size, "horizon": o.max_steps + 1}
    factory = "openral_mjx.benchmarks.robosuite.worker_env:RobosuiteEnv"
    return panda_osc_scene(
        "robosuite",
        o.task,
        o,
        factory,
        kwargs,
        observation,
        o.max_steps,
        o.gl,
        instruction=INSTRUCTIONS[o.task],
    )


# `SCENES`'s entry for `robosuite` (registered by reference in `openral_mjx.scenes`)
SCENE = SceneEntry(
    RobosuiteOptions,
    robosuite,
    ROBOT,
    backends=("host",),
    worker_env=ENV,
    tasks=", ".join(OBJECT_SIZE),
)
