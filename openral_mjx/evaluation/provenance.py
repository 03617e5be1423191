"""What produced a result: package versions and the device that ran the physics."""

from __future__ import annotations

import importlib.metadata
import platform

import openral_mjx
from openral_mjx.scenes import Scene

_PACKAGES = ("jax", "jaxlib", "mujoco", "mujoco-mjx", "flax", "numpy")


def package_versions() -> dict[str, str]:
    """Versions of Python and the packages that decide a result (source-tree runs included)."""
    out = {"python": platform.python_version(), "openral_mjx": openral_mjx.__version__}
    for name in _PACKAGES:
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


def device_description(scene: Scene) -> str:
    """What ran the physics: the JAX devices for `mjx`/`warp`, the CPU thread pool for `c`,
    worker processes for host scenes."""
    label = getattr(scene.backend, "device_label", None)
    if label is not None:
        return label()
    if scene.backend.name == "c":
        return f"cpu: MuJoCo C, {scene.backend.describe()['threads']} threads"
    devices = scene.backend.devices()
    return f"{devices[0].platform}: {devices[0].device_kind} x{len(devices)}"
