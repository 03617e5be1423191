"""Headless OpenGL for MuJoCo's renderer: find a working backend, render frames offscreen.

`import mujoco` binds its GL backend from `MUJOCO_GL` once, and PyOpenGL fixes its platform
on first use, so a failed attempt cannot be retried in-process. `gl_backend()` therefore
probes the candidates (the user's `MUJOCO_GL` if set, else EGL, then OSMesa, then GLFW where
there is a display) each in a short subprocess, and `FrameRenderer` creates a context of the
winner directly. EGL with Mesa renders in software (llvmpipe) on a machine without a GPU and
on the GPU's driver where there is one.
"""

from __future__ import annotations

import functools
import importlib
import os
import subprocess
import sys
from typing import Any

import mujoco
import numpy as np

from openral_mjx.core.errors import ConfigError

_PROBE = """
import importlib, sys
import mujoco
ctx = importlib.import_module("mujoco." + sys.argv[1]).GLContext(16, 16)
ctx.make_current()
m = mujoco.MjModel.from_xml_string("<mujoco><worldbody><geom size='1'/></worldbody></mujoco>")
mujoco.MjrContext(m, mujoco.mjtFontScale.mjFONTSCALE_100).free()
ctx.free()
"""
_FIX = (
    "on Debian/Ubuntu install Mesa's EGL (apt-get install libegl1 libegl-mesa0 "
    "libgl1-mesa-dri) or OSMesa (apt-get install libosmesa6)"
)


class GLUnavailable(ConfigError):
    """No OpenGL backend can render here (a `ConfigError`: one line, exit code 2)."""


def _candidates() -> tuple[str, ...]:
    chosen = os.environ.get("MUJOCO_GL", "").strip().lower()
    if chosen in ("egl", "osmesa", "glfw"):
        return (chosen,)
    if chosen:
        raise GLUnavailable(
            f"MUJOCO_GL={chosen!r} cannot render offscreen; valid: egl, osmesa, glfw"
        )
    display = os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
    return ("egl", "osmesa", "glfw") if display else ("egl", "osmesa")


def _probe(name: str) -> str | None:
    """None if backend `name` can create a MuJoCo rendering context here, else why not."""
    env = {**os.environ, "MUJOCO_GL": name}
    try:
        proc = subprocess.run(
            [sys.executable, "-c", _PROBE, name],
            env=env,
            capture_output=True,
            text=True,
            timeout=60,
            check=False,
        )
    except subprocess.TimeoutExpired:
        return "timed out"
    if proc.returncode == 0:
        return None
    lines = [ln.strip() for ln in proc.stderr.strip().splitlines() if ln.strip()]
    return lines[-1][:160] if lines else f"exit code {proc.returncode}"


@functools.cache
def gl_backend() -> str:
    """The first GL backend that works here (cached); `GLUnavailable` if none does."""
    failures = []
    for name in _candidates():
        why = _probe(name)
        if why is None:
            return name
        failures.append(f"{name}: {why}")
    raise GLUnavailable(f"no OpenGL backend can render here ({'; '.join(failures)}); {_FIX}")


class FrameRenderer:
    """Offscreen RGB frames of a model's named cameras through a `gl_backend()` context.

    Shadows and reflections are off unless asked for (MuJoCo's defaults, as
    `mujoco.Renderer` draws): in software GL they cost 10-30x the rest of a frame. `sites`
    False hides every site (drawn by default); `textures` False draws no textures and no
    skybox; `groups`: the geom groups drawn (default MuJoCo's, 0-2). `model` is modified
    (offscreen buffer size), so pass a copy you own.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        width: int,
        height: int,
        gl: str,
        *,
        shadows: bool = False,
        reflections: bool = False,
        sites: bool = True,
        textures: bool = True,
        groups: tuple[int, ...] | None = None,
    ) -> None:
        self.model = model
        model.vis.global_.offwidth = max(model.vis.global_.offwidth, width)
        model.vis.global_.offheight = max(model.vis.global_.offheight, height)
        self._ctx: Any = importlib.import_module(f"mujoco.{gl}").GLContext(width, height)
        self._ctx.make_current()
        self._mjr = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_150)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, self._mjr)
        self._scene = mujoco.MjvScene(model, maxgeom=10_000)
        self._scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = shadows
        self._scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = reflections
        self._option = mujoco.MjvOption()
        if not sites:
            self._option.sitegroup[:] = 0
        if groups is not None:
            self._option.geomgroup[:] = [g in groups for g in range(len(self._option.geomgroup))]
        self._option.flags[mujoco.mjtVisFlag.mjVIS_TEXTURE] = textures
        self._scene.flags[mujoco.mjtRndFlag.mjRND_SKYBOX] = textures
        self._camera = mujoco.MjvCamera()
        self._camera.type = mujoco.mjtCamera.mjCAMERA_FIXED
        self._rect = mujoco.MjrRect(0, 0, width, height)
        self._pixels = np.empty((height, width, 3), np.uint8)

    def render(
        self, data: mujoco.MjData, camera_id: int, model: mujoco.MjModel | None = None
    ) -> np.ndarray:
        """The (height, width, 3) uint8 image of camera `camera_id` for `data` (forwarded),
        upright (row 0 at the top). `model`: a copy of the renderer's model with other
        poses or colours (same meshes and textures), where `data` belongs to one."""
        self._ctx.make_current()
        self._camera.fixedcamid = camera_id
        mujoco.mjv_updateScene(
            self.model if model is None else model,
            data,
            self._option,
            None,
            self._camera,
            mujoco.mjtCatBit.mjCAT_ALL,
            self._scene,
        )
        mujoco.mjr_render(self._rect, self._scene, self._mjr)
        mujoco.mjr_readPixels(self._pixels, None, self._rect, self._mjr)
        return np.flipud(self._pixels).copy()

    def close(self) -> None:
        """Free the GL resources (explicitly: at interpreter exit GL may already be gone)."""
        if self._ctx is not None:
            self._mjr.free()
            self._ctx.free()
            self._ctx = None

    def __enter__(self) -> FrameRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def camera_id(model: mujoco.MjModel, name: str) -> int:
    """The id of camera `name`; a `ConfigError` naming the model's cameras if there is none."""
    names = [model.camera(i).name for i in range(model.ncam)]
    if name not in names:
        raise ConfigError(f"unknown camera {name!r}; valid: {', '.join(names) or '(none)'}")
    return names.index(name)
