"""RGB cameras on the `c` backend: MuJoCo's own OpenGL renderer, inside the host callback.

Each env's state is loaded into one `MjData`, forwarded (`mj_forward`: the poses of the state
itself) and drawn by `gl.FrameRenderer`, headless (EGL, Mesa's software rasteriser on a machine
without a GPU; `gl.gl_backend` picks). A GL context belongs to the thread it is current on, and
XLA may call back from any thread, so one thread of our own owns the contexts and draws every
image. How `RgbStyle` maps onto MuJoCo's renderer: `textures` switches the materials' textures
(`mjVIS_TEXTURE`) and the skybox, `shadows` the shadows and reflections (MuJoCo draws both by
default); anti-aliasing is the model's own multisampling (``visual/quality/offsamples``), so
`samples` is not read. Images come back upright (row 0 at the top), uint8.
"""

from __future__ import annotations

import concurrent.futures
import copy
from collections.abc import Sequence

import mujoco
import numpy as np

from openral_mjx.physics.cameras import RgbSpec, RgbStyle
from openral_mjx.physics.gl import FrameRenderer, camera_id, gl_backend

_FULL = mujoco.mjtState.mjSTATE_FULLPHYSICS


class HostCameras:
    """Draws `specs`' cameras of `model`'s states (FULLPHYSICS state vectors) on the host."""

    def __init__(self, model: mujoco.MjModel, specs: Sequence[RgbSpec]) -> None:
        self.model = model
        self.specs = tuple(specs)
        self.camera_ids = tuple(camera_id(model, s.camera) for s in self.specs)
        self.gl = gl_backend()  # a one-line `GLUnavailable` here, not at the first step
        self._thread: concurrent.futures.ThreadPoolExecutor | None = None
        self._renderers: dict[tuple[int, int, RgbStyle, tuple[int, ...]], FrameRenderer] = {}
        self._data: mujoco.MjData | None = None

    def render(
        self, states: np.ndarray, models: Sequence[mujoco.MjModel] | None = None
    ) -> dict[str, np.ndarray]:
        """Each camera's images (n, H, W, 3) uint8 of `states` (n, nstate); `models`: env i's
        own copy of the model (per-env fields), else the model itself."""
        if self._thread is None:
            self._thread = concurrent.futures.ThreadPoolExecutor(1, "openral_mjx_gl")
        return self._thread.submit(self._draw, np.asarray(states, np.float64), models).result()

    def _renderer(self, spec: RgbSpec) -> FrameRenderer:
        key = (spec.width, spec.height, spec.style, spec.groups)
        if key not in self._renderers:
            style = spec.style
            r = FrameRenderer(
                copy.copy(self.model),  # it sizes the model's offscreen buffer
                spec.width,
                spec.height,
                self.gl,
                shadows=style.shadows,
                reflections=style.shadows,
                textures=style.textures,
                groups=spec.groups,
            )
            self._renderers[key] = r
        return self._renderers[key]

    def _draw(
        self, states: np.ndarray, models: Sequence[mujoco.MjModel] | None
    ) -> dict[str, np.ndarray]:
        if self._data is None:
            self._data = mujoco.MjData(self.model)
        d = self._data
        out = {s.key: np.empty((len(states), s.height, s.width, 3), np.uint8) for s in self.specs}
        for i, state in enumerate(states):
            m = self.model if models is None else models[i]
            mujoco.mj_setState(m, d, np.ascontiguousarray(state), _FULL)
            mujoco.mj_forward(m, d)
            for spec, cam in zip(self.specs, self.camera_ids, strict=True):
                out[spec.key][i] = self._renderer(spec).render(d, cam, m)
        return out

    def close(self) -> None:
        """Free the GL contexts (on the thread that owns them) and stop the thread."""
        if self._thread is None:
            return

        def free() -> None:
            for r in self._renderers.values():
                r.close()
            self._renderers.clear()

        try:
            self._thread.submit(free).result()
        except RuntimeError:  # at interpreter exit the executor is already shut down
            self._renderers.clear()  # the process's end releases the contexts
        self._thread.shutdown()
        self._thread = None
