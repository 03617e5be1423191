"""Scenes and the `SCENES` registry: a scene is one registered `SceneEntry`."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from openral_mjx.errors import ConfigError
from openral_mjx.options import from_mapping
from openral_mjx.physics import PhysicsSettings
from openral_mjx.registry import Registry
from openral_mjx.scenes.base import Scene, State
from openral_mjx.scenes.so101_box import So101Box, So101BoxOptions
from openral_mjx.scenes.tabletop_push import TabletopPush, TabletopPushOptions


@dataclasses.dataclass(frozen=True)
class SceneEntry:
    """How to build a scene: its options class, its constructor, and a fixed robot if any."""

    options_cls: type
    build: Callable[..., Scene]
    fixed_robot: str | None = None


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


def make_scene(
    name: str,
    overrides: Mapping[str, Any] | None = None,
    *,
    backend: str = "auto",
    settings: PhysicsSettings | None = None,
) -> Scene:
    """Build scene `name` with option `overrides` (validated) on `backend` run with `settings`."""
    entry = SCENES.get(name)
    overrides = dict(overrides or {})
    check_robot(name, overrides.get("robot"), overrides.get("robot_mjcf"))
    if entry.fixed_robot is not None:
        overrides.pop("robot_mjcf", None)  # None here: a fixed-robot scene takes no MJCF
    options = from_mapping(entry.options_cls, overrides)
    return entry.build(options, backend=backend, settings=settings)


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
    "make_scene",
]
