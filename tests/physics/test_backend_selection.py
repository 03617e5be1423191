"""`--backend auto` picks warp > mjx > c by what the machine has; a missing extra is an error."""

import pytest

import openral_mjx.physics as physics
import openral_mjx.physics.warp_backend as warp_backend
from openral_mjx.core.errors import ConfigError
from openral_mjx.scenes import make_scene


@pytest.mark.parametrize(
    "platform,has_warp,expected",
    [
        ("cpu", False, "c"),
        ("cpu", True, "c"),  # Warp's CPU mode is for tests, not faster than MuJoCo C
        ("gpu", True, "warp"),
        ("gpu", False, "mjx"),
        ("tpu", False, "mjx"),
    ],
)
def test_auto(monkeypatch, platform, has_warp, expected):
    monkeypatch.setattr(physics.jax, "default_backend", lambda: platform)
    monkeypatch.setattr(physics, "warp_installed", lambda: has_warp)
    assert physics.resolve_backend_name("auto") == expected


def test_explicit_names_pass_through():
    for name in ("mjx", "warp", "c"):
        assert physics.resolve_backend_name(name) == name
    with pytest.raises(ConfigError, match="unknown backend 'gpu'; valid: auto, mjx, warp, c"):
        physics.resolve_backend_name("gpu")


def test_warp_without_warp_lang_names_the_install(monkeypatch):
    monkeypatch.setattr(warp_backend, "warp_installed", lambda: False)
    with pytest.raises(ConfigError, match=r"needs warp-lang; install it with pip install"):
        make_scene("tabletop_push", backend="warp")
