"""Policies and the `POLICIES` registry.

A registry entry is a factory `(scene, arg) -> Policy`; `arg` is the text after `name:` on the
command line (e.g. the checkpoint directory of `mlp:DIR`), or None. Factories read what they
need from the scene (action size and bounds, or the scene's own scripted expert) without
importing scenes.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from openral_mjx.core.errors import ConfigError
from openral_mjx.core.registry import Registry
from openral_mjx.policies.base import Policy
from openral_mjx.policies.depth_cnn import depth_cnn_policy
from openral_mjx.policies.lerobot import lerobot_policy
from openral_mjx.policies.mlp import check_compatible, load_mlp, mlp_policy
from openral_mjx.policies.simple import random_policy, zero_policy
from openral_mjx.policies.torch_policy import torch_policy

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
    if not hasattr(scene, "scripted_policy"):
        raise ConfigError(f"scene {scene.name!r} has no scripted policy; try zero, random")
    return scene.scripted_policy()


def _load_mlp_for(name: str, scene: Any, arg: str | None, deterministic: bool) -> Policy:
    if not arg:
        raise ConfigError(f"policy {name!r} needs a checkpoint directory: --policy {name}:DIR")
    config, params = load_mlp(Path(arg))
    check_compatible(config, scene, f"mlp checkpoint {arg!r}")
    return mlp_policy(config, params, deterministic=deterministic)


@POLICIES.register("mlp")
def _mlp(scene: Any, arg: str | None) -> Policy:
    """A saved flax Gaussian MLP, acting with its mean."""
    return _load_mlp_for("mlp", scene, arg, deterministic=True)


@POLICIES.register("mlp-sample")
def _mlp_sample(scene: Any, arg: str | None) -> Policy:
    """A saved flax Gaussian MLP, sampling its actions (seeded per episode)."""
    return _load_mlp_for("mlp-sample", scene, arg, deterministic=False)


@POLICIES.register("depth_cnn")
def _depth_cnn(scene: Any, arg: str | None) -> Policy:
    """A small random-weight CNN on a depth image of the observation (`depth_cnn:SLICE`)."""
    return depth_cnn_policy(scene.obs_layout, scene.obs_shapes, *scene.action_bounds(), arg)


POLICIES.register("lerobot")(lerobot_policy)
POLICIES.register("torch")(torch_policy)
# a benchmark folder's expert imports this package: registered by reference
POLICIES.register_lazy(
    "metaworld-expert", "openral_mjx.benchmarks.metaworld.expert:metaworld_expert"
)
POLICIES.register_lazy("libero-expert", "openral_mjx.benchmarks.libero.expert:libero_expert")


def make_policy(spec: str, scene: Any) -> Policy:
    """Build a policy from `name` or `name:arg` for `scene`."""
    name, sep, arg = spec.partition(":")
    return POLICIES.get(name)(scene, arg if sep else None)


__all__ = ["POLICIES", "Policy", "make_policy"]
