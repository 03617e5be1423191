"""Scenes and the `SCENES` registry: a scene is one registered `SceneEntry`."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from typing import Any

from openral_mjx.errors import ConfigError
from openral_mjx.options import from_mapping
from openral_mjx.physics import PhysicsSettings
from openral_mjx.registry import Registry
from openral_mjx.scenes.base import Scene, State
from openral_mjx.scenes.tabletop_push import TabletopPush, TabletopPushOptions


@dataclasses.dataclass(frozen=True)
class SceneEntry:
    """How to build a scene: its options class, its constructor, and a fixed robot if any."""

    options_cls: type
    build: Callable[..., Scene]
    fixed_robot: str | None = None


SCENES: Registry[SceneEntry] = Registry("scene")
SCENES.register("tabletop_push")(SceneEntry(TabletopPushOptions, TabletopPush))


def make_scene(
    name: str,
    overrides: Mapping[str, Any] | None = None,
    *,
    backend: str = "auto",
    settings: PhysicsSettings | None = None,
) -> Scene:
    """Build scene `name` with option `overrides` (validated) on `backend` run with `settings`."""
    entry = SCENES.get(name)
    options = from_mapping(entry.options_cls, dict(overrides or {}))
    robot = getattr(options, "robot", None)
    if entry.fixed_robot is not None and robot not in (None, entry.fixed_robot):
        raise ConfigError(f"scene {name!r} requires robot {entry.fixed_robot!r}, not {robot!r}")
    return entry.build(options, backend=backend, settings=settings)


__all__ = [
    "SCENES",
    "Scene",
    "SceneEntry",
    "State",
    "TabletopPush",
    "TabletopPushOptions",
    "make_scene",
]
