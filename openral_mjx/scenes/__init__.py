"""Scenes and the `SCENES` registry: a scene is one registered `SceneEntry`."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from openral_mjx.core.errors import ConfigError
from openral_mjx.core.options import from_mapping
from openral_mjx.core.registry import Registry
from openral_mjx.physics import PhysicsSettings, resolve_backend_name
from openral_mjx.scenes.base import Scene, State
from openral_mjx.scenes.point_reach import PointReachOptions, point_reach
from openral_mjx.scenes.so101_box import So101Box, So101BoxOptions
from openral_mjx.scenes.tabletop_push import TabletopPush, TabletopPushOptions


@dataclasses.dataclass(frozen=True)
class SceneEntry:
    """How to build a scene: its options class, its constructor, a fixed robot if any, the
    physics backends it runs on (None: every MuJoCo backend; host scenes: `host`), its tasks
    and suites, and the worker environment (`openral_mjx.host.envs`) its simulator or assets
    come from, if any. `eval --list` and `eval --help` read the tasks and suites from here."""

    options_cls: type
    build: Callable[..., Scene]
    fixed_robot: str | None = None
    backends: tuple[str, ...] | None = None
    suites: Callable[[str], list[str]] | None = None  # suite name -> its tasks
    worker_env: str | None = None
    tasks: str | None = None  # how `--task` names a task, one line with examples; None: one task
    suite_names: tuple[str, ...] = ()  # the names `suites` takes, in the benchmark's order
    # the policy ID of the expert its benchmark ships, for a scene with no `scripted_policy`
    # of its own (`--policy scripted` there names it rather than only zero and random)
    expert: str | None = None
    # the scene this one mirrors seed for seed (its original benchmark run through the host
    # adapter): seed s is the same initial state on both, so their reports pair by seed
    mirrors: str | None = None
    # the options that choose which initial state a seed starts from (LIBERO's protocol):
    # two reports pair seed by seed only where they agree on them (`seed_options`)
    seed_options: tuple[str, ...] = ()
    # those of them that count the initial states a seed cycles through (seed s starts from
    # state s mod count): reports whose counts differ still pair on the seeds below both
    seed_cycles: tuple[str, ...] = ()
    # the `warp` contact capacity per env its models need (None: `PhysicsSettings`'s), where
    # `--contacts-per-env` does not set one
    contacts_per_env: int | None = None
    # each task's default episode length in control steps, where a scene's tasks differ in it
    # (LIBERO's suites: 280 to 520): a pool of task processes starts the longest first
    task_steps: Callable[[str], int] | None = None

    def __post_init__(self) -> None:
        if (self.suites is None) != (not self.suite_names):
            raise ValueError("a SceneEntry with suites names them in suite_names, and only then")


SCENES: Registry[SceneEntry] = Registry("scene")
SCENES.register("tabletop_push")(SceneEntry(TabletopPushOptions, TabletopPush))
SCENES.register("so101_box")(SceneEntry(So101BoxOptions, So101Box, fixed_robot="so101"))


def check_robot(name: str, robot: str | None, robot_mjcf: str | None = None) -> None:
    """Raise `ConfigError` naming the required robot if scene `name` fixes another one."""
    fixed = SCENES.get(name).fixed_robot
    if fixed is None:
        return
    asked = robot if robot_mjcf is None else f"mjcf:{Path(str(robot_mjcf)).name}"
    if asked not in (None, fixed):
        raise ConfigError(f"scene {name!r} requires robot {fixed!r}, not {asked!r}")


SCENES.register("point_reach")(SceneEntry(PointReachOptions, point_reach, backends=("host",)))
# Public benchmarks' scenes live in their folders (`openral_mjx.benchmarks.<name>`), each
# module's `SCENE` its entry; they import this package, so they are registered by reference.
SCENES.register_lazy("libero", "openral_mjx.benchmarks.libero.host_scene:SCENE")
SCENES.register_lazy("libero_mjx", "openral_mjx.benchmarks.libero.mirror:SCENE")
SCENES.register_lazy("robosuite", "openral_mjx.benchmarks.robosuite.host_scene:SCENE")
SCENES.register_lazy("metaworld", "openral_mjx.benchmarks.metaworld.host_scene:SCENE")
SCENES.register_lazy("metaworld_mjx", "openral_mjx.benchmarks.metaworld.mirror:SCENE")
SCENES.register_lazy("pusht", "openral_mjx.benchmarks.pusht.host_scene:SCENE")
SCENES.register_lazy("aloha", "openral_mjx.benchmarks.aloha.host_scene:SCENE")
SCENES.register_lazy("maniskill", "openral_mjx.benchmarks.maniskill.host_scene:SCENE")


def check_task(name: str, task: str | None) -> bool:
    """Whether `--task` is a scene option of scene `name` (multi-task scenes); a single-task
    scene takes only its own task's name (then False), any other is a `ConfigError` naming it
    and the scene's task."""
    entry = SCENES.get(name)
    if task is None or "task" in {f.name for f in dataclasses.fields(entry.options_cls)}:
        return task is not None
    own = getattr(entry.build, "task", None)
    if task == own:
        return False
    raise ConfigError(f"unknown task {task!r} for scene {name!r}; valid: {own} (its only task)")


def scene_settings(
    name: str, contacts_per_env: int | None = None, **fields: Any
) -> PhysicsSettings:
    """`PhysicsSettings(**fields)` for scene `name`: its `warp` contact capacity is
    `contacts_per_env` if given, else the scene's own (`SceneEntry.contacts_per_env`), else
    the settings' default, so every caller that builds a scene sizes its buffers alike."""
    if contacts_per_env is None and name in SCENES:
        contacts_per_env = SCENES.get(name).contacts_per_env
    if contacts_per_env is not None:
        fields["contacts_per_env"] = contacts_per_env
    return PhysicsSettings(**fields)


def mirrored(a: str, b: str) -> bool:
    """Whether scenes `a` and `b` differ and one mirrors the other (`SceneEntry.mirrors`)."""
    if a == b or a not in SCENES or b not in SCENES:
        return False
    return SCENES.get(a).mirrors == b or SCENES.get(b).mirrors == a


def seed_options(a: str, b: str) -> dict[str, Any]:
    """The options of scenes `a` and `b` that choose which initial state a seed starts from
    (`SceneEntry.seed_options`), each with its default: a report that does not record one
    ran with the default."""
    out: dict[str, Any] = {}
    for name in {a, b} & set(SCENES.names()):
        entry = SCENES.get(name)
        defaults = {f.name: f.default for f in dataclasses.fields(entry.options_cls)}
        out |= {key: defaults.get(key) for key in entry.seed_options}
    return out


def seed_cycles(a: str, b: str) -> tuple[str, ...]:
    """The seed options of scenes `a` and `b` that count the initial states a seed cycles
    through (`SceneEntry.seed_cycles`)."""
    names = sorted({a, b} & set(SCENES.names()))
    return tuple(sorted({key for name in names for key in SCENES.get(name).seed_cycles}))


def scripted_policy(name: str, policy: str) -> str:
    """The policy to run for `--policy policy` on scene `name`: `scripted` means the scene's
    scripted expert, which for a scene without a `scripted_policy` of its own is the expert
    its benchmark ships (`SceneEntry.expert`); with neither, a `ConfigError` before anything
    is built. Any other policy is returned unchanged."""
    entry = SCENES.get(name)
    if policy != "scripted" or hasattr(entry.build, "scripted_policy"):
        return policy
    if entry.expert is None:
        raise ConfigError(f"scene {name!r} has no scripted policy; try zero, random")
    return entry.expert


def scene_suite(name: str, suite: str) -> list[str]:
    """The tasks of `suite` in scene `name` (a `ConfigError` for scenes without suites).

    `suite` may name several, comma-separated (as lerobot's LIBERO evaluation takes
    ``libero_spatial,libero_object,libero_goal,libero_10``): their tasks in that order."""
    entry = SCENES.get(name)
    if entry.suites is None:
        with_suites = [n for n in SCENES.names() if SCENES.get(n).suites is not None]
        raise ConfigError(
            f"scene {name!r} has no task suites (--suite is for {', '.join(with_suites)})"
        )
    names = suite_names(suite)
    for repeated in {n for n in names if names.count(n) > 1}:
        raise ConfigError(f"suite {repeated!r} is named twice in {suite!r}")
    tasks: list[str] = []
    for one in names:
        mine = entry.suites(one)
        if shared := sorted(set(tasks) & set(mine)):  # e.g. MetaWorld's mt10 is part of mt50
            raise ConfigError(f"suites in {suite!r} share tasks ({', '.join(shared[:3])}, ...)")
        tasks += mine
    return tasks


def longest_first(name: str, tasks: Sequence[str], max_steps: int | None = None) -> list[int]:
    """The indices of scene `name`'s `tasks`, those with the longest episodes first (each
    task's `SceneEntry.task_steps`, capped at `max_steps`), in their given order among equals.

    A pool of processes that takes tasks in this order ends sooner: the longest tasks do not
    come last, to run while the other processes idle (Graham's longest-processing-time rule,
    within 4/3 of the best order). Every task keeps its own seeds, so no episode changes."""
    steps = SCENES.get(name).task_steps
    if steps is None:
        return list(range(len(tasks)))
    cap = max_steps if max_steps is not None else float("inf")
    return sorted(range(len(tasks)), key=lambda i: -min(steps(tasks[i]), cap))


def suite_names(suite: str) -> list[str]:
    """The suites a `--suite` value names (comma-separated), each stripped; an empty name is a
    `ConfigError`."""
    names = [n.strip() for n in suite.split(",")]
    if not all(names):
        raise ConfigError(f"--suite {suite!r} has an empty suite name")
    return names


def resolve_scene_backend(name: str, backend: str) -> str:
    """The backend scene `name` runs on for the `--backend` value `backend` (`auto` resolved);
    a backend the scene cannot run on is a `ConfigError`."""
    entry = SCENES.get(name)
    if entry.backends is None:
        if backend == "host":
            raise ConfigError(f"scene {name!r} runs on a MuJoCo backend, not 'host'")
        return resolve_backend_name(backend)
    if backend == "auto":
        return entry.backends[0]
    if backend not in entry.backends:
        raise ConfigError(
            f"scene {name!r} runs on backend {', '.join(entry.backends)}, not {backend!r}"
        )
    return backend


def make_scene(
    name: str,
    overrides: Mapping[str, Any] | None = None,
    *,
    backend: str = "auto",
    settings: PhysicsSettings | None = None,
) -> Scene:
    """Build scene `name` with option `overrides` (validated) on `backend` run with `settings`."""
    entry = SCENES.get(name)
    if entry.backends is not None:  # host scenes: refuse a MuJoCo backend rather than ignore it
        resolve_scene_backend(name, backend)
    options = scene_options(name, overrides)
    return entry.build(options, backend=backend, settings=settings)


def scene_options(name: str, overrides: Mapping[str, Any] | None = None) -> Any:
    """Scene `name`'s options dataclass with `overrides` applied and checked (unknown keys,
    types, ranges, a robot the scene does not take: `ConfigError`), without building it."""
    entry = SCENES.get(name)
    overrides = dict(overrides or {})
    check_robot(name, overrides.get("robot"), overrides.get("robot_mjcf"))
    if entry.fixed_robot is not None:
        overrides.pop("robot_mjcf", None)  # None here: a fixed-robot scene takes no MJCF
    return from_mapping(entry.options_cls, overrides)


__all__ = [
    "SCENES",
    "Scene",
    "SceneEntry",
    "So101Box",
    "So101BoxOptions",
    "State",
    "TabletopPush",
    "TabletopPushOptions",
    "check_robot",
    "check_task",
    "longest_first",
    "make_scene",
    "mirrored",
    "resolve_scene_backend",
    "scene_options",
    "scene_suite",
    "scripted_policy",
    "suite_names",
]
