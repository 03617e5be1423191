"""`libero`: LIBERO tasks (robosuite, CPU) in worker processes, through the host adapter.

Task ``SUITE/INDEX`` (`libero_spatial`, `libero_object`, `libero_goal`, `libero_10`,
`libero_90`) runs LIBERO's shipped BDDL file; seed s starts from the task's shipped initial
state ``s mod 50`` (LIBERO's protocol evaluates initial states 0..49, i.e. seeds 0..49), or
with option ``protocol=sampled`` from LIBERO's own reset draw with numpy seeded by s (mod
`sampled_states`, default 1,024). Observation: ``image`` and
``wrist_image`` (RGB uint8, `image_size` square, upright) and ``state`` (end-effector position,
axis-angle, gripper fingers: 8 floats), as lerobot's LIBERO policies expect; with
``image_size=null`` LIBERO renders nothing and the observation is one flat vector (``state``,
then ``expert``), as on `libero_mjx` without cameras, for policies on the state (mlp).
Action: 7-D OSC pose delta and gripper in [-1, 1], 20 Hz. Success: LIBERO's goal predicates.
Cameras render offscreen through EGL (Mesa's software rasteriser on a CPU-only machine, a GPU's
where there is one). Instruction: the task's own language (`instructions`). The simulator runs
in the ``lerobot-libero`` worker environment, created on first use (see `openral_mjx.host.envs`).
"""

from __future__ import annotations

import dataclasses

from openral_mjx.benchmarks.libero.export import EXPERT_SIZE
from openral_mjx.benchmarks.libero.instructions import INSTRUCTIONS
from openral_mjx.benchmarks.robosuite.host_scene import ENV, ROBOT, panda_osc_scene
from openral_mjx.core.errors import ConfigError, unknown
from openral_mjx.core.options import check
from openral_mjx.scenes import SceneEntry
from openral_mjx.scenes.host_scene import HostOptions, HostScene

# Tasks per suite and episode limits (lerobot's: the longest training demonstration + margin).
SUITES = {
    "libero_spatial": (10, 280),
    "libero_object": (10, 280),
    "libero_goal": (10, 300),
    "libero_10": (10, 520),
    "libero_90": (90, 400),
}
INIT_STATES = 50  # shipped initial states per task
PROTOCOLS = ("standard", "sampled")
SAMPLED_STATES = 1024  # the mass-seed protocol's default count of drawn initial states


def check_protocol(protocol: str, sampled_states: int) -> None:
    """The initial-state options shared by `libero` and `libero_mjx`, checked."""
    check(protocol in PROTOCOLS, f"option protocol={protocol!r}; valid: {', '.join(PROTOCOLS)}")
    check(sampled_states >= 1, f"option sampled_states={sampled_states}: must be >= 1")


def init_state_count(protocol: str, sampled_states: int) -> int:
    """How many distinct initial states seeds cycle through: LIBERO's 50 shipped ones, or the
    mass-seed protocol's `sampled_states` draws (seed s starts from state s mod that count)."""
    return INIT_STATES if protocol == "standard" else sampled_states


def parse_task(task: str) -> tuple[str, int]:
    """``suite/index`` -> (suite, index), or a `ConfigError` naming the valid ones."""
    suite, sep, index = task.partition("/")
    if suite not in SUITES:
        raise unknown("LIBERO suite", suite, SUITES)
    if not sep or not index.isdigit() or int(index) >= SUITES[suite][0]:
        raise ConfigError(
            f"LIBERO task {task!r}: expected {suite}/<index> with index 0..{SUITES[suite][0] - 1}"
        )
    return suite, int(index)


def suite_tasks(suite: str) -> list[str]:
    """Every task of `suite`, in LIBERO's order."""
    if suite not in SUITES:
        raise unknown("LIBERO suite", suite, SUITES)
    return [f"{suite}/{i}" for i in range(SUITES[suite][0])]


def task_steps(task: str) -> int:
    """The episode limit of ``suite/index``: its suite's (lerobot's)."""
    return SUITES[parse_task(task)[0]][1]


def instruction(task: str) -> str:
    """LIBERO's language instruction of ``suite/index`` (see `instructions`)."""
    suite, index = parse_task(task)
    return INSTRUCTIONS[suite][index]


@dataclasses.dataclass(frozen=True)
class LiberoOptions(HostOptions):
    """`libero` options: the task, the camera resolution (None, ``null`` on the command
    line: no cameras, a flat vector), the episode limit (default: the suite's), the offscreen
    GL platform (`egl`, or `osmesa` where EGL is missing), whether
    the observation has the ``expert`` entry that `libero-expert` reads, and the initial
    states: `protocol` ``standard`` (LIBERO's 50 shipped states, seed s -> state s mod 50) or
    ``sampled`` (LIBERO's own reset draws the objects, fixtures and joints from the task's
    BDDL regions, numpy seeded with s mod `sampled_states`: thousands of distinct seeds)."""

    task: str = "libero_spatial/0"
    image_size: int | None = 128
    max_steps: int | None = None
    gl: str = "egl"
    expert: bool = True
    protocol: str = "standard"
    sampled_states: int = SAMPLED_STATES

    def __post_init__(self) -> None:
        super().__post_init__()
        parse_task(self.task)
        check_protocol(self.protocol, self.sampled_states)
        if self.image_size is not None:
            check(self.image_size >= 8, f"option image_size={self.image_size}: must be >= 8")
        if self.max_steps is not None:
            check(self.max_steps >= 1, f"option max_steps={self.max_steps}: must be >= 1")
        check(self.gl in ("egl", "osmesa"), f"option gl={self.gl!r}; valid: egl, osmesa")


def libero(options: LiberoOptions, **_: object) -> HostScene:
    o = options
    size = o.image_size
    observation: dict = {}
    if size is not None:
        observation["image"] = ((size, size, 3), "uint8")
        observation["wrist_image"] = ((size, size, 3), "uint8")
    observation["state"] = ((8,), "float32")
    if o.expert:
        observation["expert"] = ((EXPERT_SIZE,), "float32")
    return panda_osc_scene(
        "libero",
        o.task,
        o,
        "openral_mjx.benchmarks.libero.worker_env:LiberoEnv",
        {"task": o.task, "image_size": size, "expert": o.expert},
        observation,
        o.max_steps or task_steps(o.task),
        o.gl,
        n_init_states=init_state_count(o.protocol, o.sampled_states),
        reset_options={"sampled": True} if o.protocol == "sampled" else {},
        instruction=instruction(o.task),
        flat_obs=size is None,
    )


# `SCENES`'s entry for `libero` (registered by reference in `openral_mjx.scenes`)
SCENE = SceneEntry(
    LiberoOptions,
    libero,
    ROBOT,
    backends=("host",),
    suites=suite_tasks,
    worker_env=ENV,  # LIBERO runs robosuite's Panda scenes
    tasks="SUITE/INDEX (INDEX from 0), e.g. libero_spatial/0",
    suite_names=tuple(SUITES),
    expert="libero-expert",
    seed_options=("protocol", "sampled_states"),
    seed_cycles=("sampled_states",),  # seed s draws state s mod sampled_states
    task_steps=task_steps,
)
