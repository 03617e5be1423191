"""`SceneWrapper` forwards the whole `Scene` interface, so a wrapper changes only what it overrides.

`Scene` defines defaults for most members, which `__getattr__` never sees: a member missing
from the base would silently run `Scene`'s default on the wrapper instead of the scene's own.
A fake scene whose every member is a distinct sentinel catches that, with no physics built.
"""

from __future__ import annotations

import inspect
from typing import Any

import jax
import jax.numpy as jnp
import pytest

from openral_mjx.scenes.base import Scene, State
from openral_mjx.scenes.wrapper import SceneWrapper

# Derived from the wrapper's own `reset_with_seed` and `step` (as `Scene` does), not forwarded.
DERIVED = {"observation_size", "observation_spec", "state_spec", "traced"}
INTERFACE = sorted({n for n in dir(Scene) if not n.startswith("_")} | set(Scene.__annotations__))
METHODS = [n for n in INTERFACE if inspect.isfunction(getattr(Scene, n, None))]
ATTRIBUTES = [n for n in INTERFACE if n not in METHODS and n not in DERIVED]


def _recorder(name: str) -> Any:
    def method(self: Any, *args: Any) -> Any:
        self.calls.append((name, args))
        return (name, args)

    return method


def _fake_scene() -> Any:
    """A scene whose every attribute is a sentinel and every method logs its call and returns
    it, overriding each of `Scene`'s defaults."""
    members: dict[str, Any] = {n: object() for n in ATTRIBUTES}
    members |= {n: _recorder(n) for n in METHODS}
    members["scripted_action"] = object()  # an extra of the scene's own
    scene = type("Fake", (Scene,), members)()
    scene.calls = []
    return scene


def _differences(wrapper: Scene, inner: Any) -> list[str]:
    """The interface members on which `wrapper` is not `inner`: an attribute that differs, or
    a method that does not call the scene's own once with the same arguments and return what
    it returns (hooks typed `-> None` return nothing)."""
    out = [n for n in ATTRIBUTES if getattr(wrapper, n) is not getattr(inner, n)]
    for n in METHODS:
        signature = inspect.signature(getattr(Scene, n))
        args = tuple(object() for _ in list(signature.parameters)[1:])
        inner.calls.clear()
        got = getattr(wrapper, n)(*args)
        returns = None if signature.return_annotation == "None" else (n, args)
        if inner.calls != [(n, args)] or got != returns:
            out.append(n)
    return out


def test_the_interface_is_read_from_scene():
    assert {"name", "video_camera", "instruction", "obs_layout", "mj_model"} <= set(ATTRIBUTES)
    assert {"reset", "step", "reset_with_seed", "pose_frame", "policy_images"} <= set(METHODS)
    assert set(INTERFACE) >= DERIVED


def test_every_member_is_defined_on_the_base():
    # `__getattr__` does not fire for names `Scene` defines: each must be forwarded explicitly.
    missing = [n for n in INTERFACE if n not in DERIVED and n not in vars(SceneWrapper)]
    assert missing == []


def test_the_base_forwards_every_member():
    inner = _fake_scene()
    wrapper = SceneWrapper(inner)
    assert _differences(wrapper, inner) == []
    assert wrapper.scripted_action is inner.scripted_action
    with pytest.raises(AttributeError):
        wrapper.no_such_member  # noqa: B018


def test_an_override_changes_only_its_member():
    class Bounded(SceneWrapper):
        def action_bounds(self) -> Any:
            return "its own"

    inner = _fake_scene()
    assert _differences(Bounded(inner), inner) == ["action_bounds"]


class _Vector(Scene):
    """A scene observing a vector of 4."""

    name = task = "vector"

    def reset(self, key: jax.Array) -> State:
        del key
        zero = jnp.zeros(())
        return State(None, jnp.zeros(4), zero, zero, {}, {})

    def step(self, state: State, action: jax.Array) -> State:
        return state

    @property
    def obs_layout(self) -> dict[str, tuple[int, int]]:
        return {"x": (0, 4)}


def test_observation_shape_is_derived_from_the_wrapper_reset():
    class Longer(SceneWrapper):  # the reset the runner calls, `reset_with_seed`
        def reset_with_seed(self, seed: jax.Array, key: jax.Array) -> State:
            state = self.inner.reset_with_seed(seed, key)
            return state.replace(obs=jnp.concatenate([state.obs, state.obs[:2]]))

    inner = _Vector()
    assert SceneWrapper(inner).observation_size == inner.observation_size == 4
    assert SceneWrapper(inner).observation_spec == inner.observation_spec
    assert Longer(inner).observation_size == 6
    assert Longer(inner).observation_spec.shape == (6,)


def test_a_wrapper_without_inner_raises_attribute_error():
    # Before `__init__` sets `inner` (copying, a failed construction), lookups must not recurse.
    bare = SceneWrapper.__new__(SceneWrapper)
    with pytest.raises(AttributeError):
        bare.anything  # noqa: B018
