"""Policies and the `POLICIES` registry.

A registry entry is a factory `(scene, arg) -> Policy`; `arg` is the text after `name:` on the
command line (e.g. a checkpoint path), or None. Factories read what they need from the scene
(action size and bounds, or the scene's own scripted expert) without importing scenes.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from openral_mjx.errors import ConfigError
from openral_mjx.policies.base import Policy
from openral_mjx.policies.simple import random_policy, zero_policy
from openral_mjx.registry import Registry

PolicyFactory = Callable[[Any, str | None], Policy]
POLICIES: Registry[PolicyFactory] = Registry("policy")


def _no_arg(name: str, arg: str | None) -> None:
    if arg is not None:
        raise ConfigError(f"policy {name!r} takes no argument, got {name}:{arg}")


@POLICIES.register("zero")
def _zero(scene: Any, arg: str | None) -> Policy:
    _no_arg("zero", arg)
    return zero_policy(scene.action_size)


@POLICIES.register("random")
def _random(scene: Any, arg: str | None) -> Policy:
    _no_arg("random", arg)
    return random_policy(*scene.action_bounds())


@POLICIES.register("scripted")
def _scripted(scene: Any, arg: str | None) -> Policy:
    _no_arg("scripted", arg)
    return scene.scripted_policy()


def make_policy(spec: str, scene: Any) -> Policy:
    """Build a policy from `name` or `name:arg` for `scene`."""
    name, sep, arg = spec.partition(":")
    return POLICIES.get(name)(scene, arg if sep else None)


__all__ = ["POLICIES", "Policy", "make_policy"]
