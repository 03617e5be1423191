"""`metaworld`: MetaWorld v3 tasks (Sawyer, MuJoCo 3.3 on the CPU) through the host adapter.

Task: one of MetaWorld 3.1.1's 50 v3 tasks (``reach-v3``, ``push-v3``, ...); suites `mt10`,
`mt50`, `ml45-train` and `ml45-test` are MetaWorld's MT10, MT50 and ML45 task lists, in its
order. Seed s sets MetaWorld's random vector (object and goal positions): drawn in JAX from
the episode's reset key from the task's reset space, with MetaWorld's redraw rule, exactly as
the `metaworld_mjx` mirror draws it (`mirror.task.random_vector`), and handed to MetaWorld's
own frozen-vector reset, so seed s has the same initial state on every run and batch size, and
on this scene and its mirror. Observation (MetaWorld's gymnasium env):
``obs``, 39 float32 (hand, gripper, object poses, the previous frame's, goal; the goal is zeros
with ``goal_observable=false``, as in MetaWorld's ML benchmarks), ``agent_pos`` (its first 4,
lerobot's MetaWorld state), with ``image_size`` > 0 ``pixels`` (lerobot's ``corner2`` camera,
upright RGB uint8; lerobot trains at 480), and with ``expert`` (default) ``expert_action``,
the task's scripted policy's action at this observation (computed in the worker; see
``--policy metaworld-expert``). Action: 4-D hand displacement and gripper in [-1, 1] at 80 Hz
(MetaWorld's 5 substeps of 2.5 ms). Success: ``info["success"]``, which ends the episode;
MetaWorld truncates at 500 steps. Episode factors: the object's initial position and the goal
position (x, y, z): MetaWorld's ``obj_init_pos`` and ``_target_pos`` after the reset, which the
mirror reports too. Instruction: lerobot's description of the task (`INSTRUCTIONS`), also the
mirror's. Runs in the ``metaworld`` worker environment, created on first use (see
`openral_mjx.host.envs`).
"""

from __future__ import annotations

import dataclasses
import functools

from openral_mjx.core.errors import unknown
from openral_mjx.core.options import check
from openral_mjx.host.envs import ensure_env, our_mujoco_path
from openral_mjx.scenes import SceneEntry
from openral_mjx.scenes.host_scene import HostOptions, HostScene, HostSceneSpec

ENV = "metaworld"
ROBOT = "sawyer"
FACTORY = "openral_mjx.benchmarks.metaworld.worker_env:make"
FACTORS = ("obj_x", "obj_y", "obj_z", "goal_x", "goal_y", "goal_z")
OBS_SIZE = 39
ACTION_SIZE = 4
MAX_STEPS = 500  # MetaWorld's max_path_length
CONTROL_DT = 0.0125  # frame_skip 5 x timestep 2.5 ms
MUJOCOS = ("metaworld", "ours")  # MetaWorld's pinned MuJoCo, or the evaluator's (option mujoco)

# MetaWorld 3.1.1's task lists (metaworld.env_dict; tests check them against the installed
# package): every v3 task in its order, MT10, and ML45's test split (its train split is the rest).
TASKS = (
    "assembly-v3",
    "basketball-v3",
    "bin-picking-v3",
    "box-close-v3",
    "button-press-topdown-v3",
    "button-press-topdown-wall-v3",
    "button-press-v3",
    "button-press-wall-v3",
    "coffee-button-v3",
    "coffee-pull-v3",
    "coffee-push-v3",
    "dial-turn-v3",
    "disassemble-v3",
    "door-close-v3",
    "door-lock-v3",
    "door-open-v3",
    "door-unlock-v3",
    "hand-insert-v3",
    "drawer-close-v3",
    "drawer-open-v3",
    "faucet-open-v3",
    "faucet-close-v3",
    "hammer-v3",
    "handle-press-side-v3",
    "handle-press-v3",
    "handle-pull-side-v3",
    "handle-pull-v3",
    "lever-pull-v3",
    "pick-place-wall-v3",
    "pick-out-of-hole-v3",
    "pick-place-v3",
    "plate-slide-v3",
    "plate-slide-side-v3",
    "plate-slide-back-v3",
    "plate-slide-back-side-v3",
    "peg-insert-side-v3",
    "peg-unplug-side-v3",
    "soccer-v3",
    "stick-push-v3",
    "stick-pull-v3",
    "push-v3",
    "push-wall-v3",
    "push-back-v3",
    "reach-v3",
    "reach-wall-v3",
    "shelf-place-v3",
    "sweep-into-v3",
    "sweep-v3",
    "window-open-v3",
    "window-close-v3",
)
MT10 = (
    "reach-v3",
    "push-v3",
    "pick-place-v3",
    "door-open-v3",
    "drawer-open-v3",
    "drawer-close-v3",
    "button-press-topdown-v3",
    "peg-insert-side-v3",
    "window-open-v3",
    "window-close-v3",
)
ML45_TEST = ("bin-picking-v3", "box-close-v3", "hand-insert-v3", "door-lock-v3", "door-unlock-v3")
# ML45's train split in MetaWorld's own order (not TASKS' order: MetaWorld lists it separately).
ML45_TRAIN = (
    "assembly-v3",
    "basketball-v3",
    "button-press-topdown-v3",
    "button-press-topdown-wall-v3",
    "button-press-v3",
    "button-press-wall-v3",
    "coffee-button-v3",
    "coffee-pull-v3",
    "coffee-push-v3",
    "dial-turn-v3",
    "disassemble-v3",
    "door-close-v3",
    "door-open-v3",
    "drawer-close-v3",
    "drawer-open-v3",
    "faucet-open-v3",
    "faucet-close-v3",
    "hammer-v3",
    "handle-press-side-v3",
    "handle-press-v3",
    "handle-pull-side-v3",
    "handle-pull-v3",
    "lever-pull-v3",
    "pick-place-wall-v3",
    "pick-out-of-hole-v3",
    "push-back-v3",
    "pick-place-v3",
    "plate-slide-v3",
    "plate-slide-side-v3",
    "plate-slide-back-v3",
    "plate-slide-back-side-v3",
    "peg-insert-side-v3",
    "peg-unplug-side-v3",
    "soccer-v3",
    "stick-push-v3",
    "stick-pull-v3",
    "push-wall-v3",
    "push-v3",
    "reach-wall-v3",
    "reach-v3",
    "shelf-place-v3",
    "sweep-into-v3",
    "sweep-v3",
    "window-open-v3",
    "window-close-v3",
)
SUITES = {"mt10": MT10, "mt50": TASKS, "ml45-train": ML45_TRAIN, "ml45-test": ML45_TEST}

# Each task's natural-language instruction: lerobot 0.4.4's MetaWorld task descriptions
# (`TASK_DESCRIPTIONS` in its data file `lerobot/envs/metaworld_config.json`), the text its
# MetaWorld env hands VLA policies as `task`; tests check them against the installed file
# where the `lerobot-libero` worker environment exists.
INSTRUCTIONS = {
    "assembly-v3": "Pick up a nut and place it onto a peg",
    "basketball-v3": "Dunk the basketball into the basket",
    "bin-picking-v3": "Grasp the puck from one bin and place it into another bin",
    "box-close-v3": "Grasp the cover and close the box with it",
    "button-press-topdown-v3": "Press a button from the top",
    "button-press-topdown-wall-v3": "Bypass a wall and press a button from the top",
    "button-press-v3": "Press a button",
    "button-press-wall-v3": "Bypass a wall and press a button",
    "coffee-button-v3": "Push a button on the coffee machine",
    "coffee-pull-v3": "Pull a mug from a coffee machine",
    "coffee-push-v3": "Push a mug under a coffee machine",
    "dial-turn-v3": "Rotate a dial 180 degrees",
    "disassemble-v3": "Pick a nut out of a peg",
    "door-close-v3": "Close a door with a revolving joint",
    "door-lock-v3": "Lock the door by rotating the lock clockwise",
    "door-open-v3": "Open a door with a revolving joint",
    "door-unlock-v3": "Unlock the door by rotating the lock counter-clockwise",
    "hand-insert-v3": "Insert the gripper into a hole",
    "drawer-close-v3": "Push and close a drawer",
    "drawer-open-v3": "Open a drawer",
    "faucet-open-v3": "Rotate the faucet counter-clockwise",
    "faucet-close-v3": "Rotate the faucet clockwise",
    "hammer-v3": "Hammer a screw on the wall",
    "handle-press-side-v3": "Press a handle down sideways",
    "handle-press-v3": "Press a handle down",
    "handle-pull-side-v3": "Pull a handle up sideways",
    "handle-pull-v3": "Pull a handle up",
    "lever-pull-v3": "Pull a lever down 90 degrees",
    "pick-place-wall-v3": "Pick a puck, bypass a wall and place the puck",
    "pick-out-of-hole-v3": "Pick up a puck from a hole",
    "pick-place-v3": "Pick and place a puck to a goal",
    "plate-slide-v3": "Slide a plate into a cabinet",
    "plate-slide-side-v3": "Slide a plate into a cabinet sideways",
    "plate-slide-back-v3": "Get a plate from the cabinet",
    "plate-slide-back-side-v3": "Get a plate from the cabinet sideways",
    "peg-insert-side-v3": "Insert a peg sideways",
    "peg-unplug-side-v3": "Unplug a peg sideways",
    "soccer-v3": "Kick a soccer into the goal",
    "stick-push-v3": "Grasp a stick and push a box using the stick",
    "stick-pull-v3": "Grasp a stick and pull a box with the stick",
    "push-v3": "Push the puck to a goal",
    "push-wall-v3": "Bypass a wall and push a puck to a goal",
    "push-back-v3": "Push the puck to a goal",
    "reach-v3": "Reach a goal position",
    "reach-wall-v3": "Bypass a wall and reach a goal",
    "shelf-place-v3": "Pick and place a puck onto a shelf",
    "sweep-into-v3": "Sweep a puck into a hole",
    "sweep-v3": "Sweep a puck off the table",
    "window-open-v3": "Push and open a window",
    "window-close-v3": "Push and close a window",
}


def suite_tasks(suite: str) -> list[str]:
    """Every task of MetaWorld benchmark `suite`, in MetaWorld's order."""
    if suite not in SUITES:
        raise unknown("MetaWorld suite", suite, SUITES)
    return list(SUITES[suite])


def instruction(task: str) -> str:
    """MetaWorld task `task`'s instruction (`INSTRUCTIONS`), shared by host and mirror scenes."""
    return INSTRUCTIONS[task]


@dataclasses.dataclass(frozen=True)
class MetaWorldOptions(HostOptions):
    """`metaworld` options: the task, whether the goal is observed (MT benchmarks: true; ML:
    false), the camera resolution (0: no camera; lerobot's MetaWorld policies see 480), the
    episode limit, whether the workers compute the scripted expert's action, the offscreen
    GL platform for the camera (`egl`, or `osmesa` where EGL is missing), and the MuJoCo
    MetaWorld runs on: ``metaworld``, its pinned one (3.3.0), or ``ours``, the evaluator's
    (what the mirror runs; the worker environment's Python must be the evaluator's), which
    separates the mirror's differences from the version's."""

    task: str = "reach-v3"
    goal_observable: bool = True
    image_size: int = 0
    max_steps: int = MAX_STEPS
    expert: bool = True
    gl: str = "egl"
    mujoco: str = "metaworld"

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.task not in TASKS:
            raise unknown("MetaWorld task", self.task, TASKS)
        check(self.image_size >= 0, f"option image_size={self.image_size}: must be >= 0")
        check(
            1 <= self.max_steps <= MAX_STEPS,
            f"option max_steps={self.max_steps}: must be in 1..{MAX_STEPS} (MetaWorld's limit)",
        )
        check(self.gl in ("egl", "osmesa"), f"option gl={self.gl!r}; valid: egl, osmesa")
        check(
            self.mujoco in MUJOCOS,
            f"option mujoco={self.mujoco!r}; valid: {', '.join(MUJOCOS)}",
        )


def metaworld(options: MetaWorldOptions, **_: object) -> HostScene:
    o = options
    observation: dict = {"obs": ((OBS_SIZE,), "float32"), "agent_pos": ((4,), "float32")}
    if o.image_size > 0:
        observation["pixels"] = ((o.image_size, o.image_size, 3), "uint8")
    if o.expert:
        observation["expert_action"] = ((ACTION_SIZE,), "float32")
    kwargs = {
        "task": o.task,
        "goal_observable": o.goal_observable,
        "image_size": o.image_size,
        "expert": o.expert,
    }
    env = {"MUJOCO_GL": o.gl, "PYOPENGL_PLATFORM": o.gl} if o.image_size > 0 else {}
    # imported here: the mirror's package imports this module
    from openral_mjx.benchmarks.metaworld.mirror.task import random_vector
    from openral_mjx.benchmarks.metaworld.mirror.tasks import TASKS as MIRROR_TASKS

    python = ensure_env(ENV)
    first = (our_mujoco_path(python),) if o.mujoco == "ours" else ()
    batch = dataclasses.replace(
        o.batch_config(FACTORY, kwargs, observation, ACTION_SIZE, env, first), factors=FACTORS
    )
    spec = HostSceneSpec(
        name="metaworld",
        task=o.task,
        robot=ROBOT,
        batch=batch,
        action_low=(-1.0,) * ACTION_SIZE,
        action_high=(1.0,) * ACTION_SIZE,
        control_dt=CONTROL_DT,
        max_steps=o.max_steps,
        instruction=instruction(o.task),
        # seed s: the mirror's random vector, which the worker's reset freezes (`rand_vec`)
        reset_draw=functools.partial(random_vector, MIRROR_TASKS[o.task]),
        reset_draw_option="rand_vec",
    )
    return HostScene(spec, o, ENV, python)


# `SCENES`'s entry for `metaworld` (registered by reference in `openral_mjx.scenes`)
SCENE = SceneEntry(
    MetaWorldOptions,
    metaworld,
    ROBOT,
    backends=("host",),
    suites=suite_tasks,
    worker_env=ENV,
    tasks=f"MetaWorld's {len(TASKS)} v3 tasks, e.g. {', '.join(MT10[:3])}",
    suite_names=tuple(SUITES),
    expert="metaworld-expert",
)
