"""Sensor observations a scene can add through its options: depth and RGB cameras, a laser.

Observations stay one flat float32 vector (the runner, the policies and training assume one);
each sensor is appended as a named slice of `Scene.obs_layout`, flattened row-major, with its
array shape in `Scene.obs_shapes`, so an image policy reshapes its slice. Depth and laser
ranges are metres, RGB is in [0, 1]. The physics backend produces the readings
(`Quantities.sensors`): ray cast from body poses on every backend, rendered by MuJoCo-Warp's
batch renderer for cameras on `warp`, by MuJoCo's OpenGL renderer on `c`.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import mujoco

from openral_mjx.core.options import check
from openral_mjx.physics import Quantities
from openral_mjx.physics.cameras import RgbSpec, RgbStyle, SensorSpec, sensor_key
from openral_mjx.raycast import DepthSpec, LaserSpec

Size = tuple[int, int]


@dataclasses.dataclass(frozen=True)
class SensorObsOptions:
    """Sensor observations, shared by the scenes' options (all off by default).

    Attributes:
        obs_depth_cameras: MJCF cameras whose depth images (metres along the optical axis)
            join the observation as `depth_CAMERA` slices.
        obs_depth_size: their (width, height) in pixels; intrinsics are the camera's own.
        obs_depth_range: (min, max) depth measured (m); pixels outside read the max.
        obs_rgb_cameras: cameras whose RGB images join as `rgb_CAMERA` (`warp`, `c`).
        obs_rgb_size: their (width, height).
        obs_rgb_textures, obs_rgb_shadows, obs_rgb_samples: how they are drawn (`RgbStyle`):
            textures and skybox, shadows, sub-pixel samples per axis (anti-aliasing).
        obs_laser_frame: body or site carrying a 2-D laser scanner (`scan` slice), e.g. the
            base of a mobile robot; the robot's own bodies are excluded from its view.
        obs_laser_beams, obs_laser_range, obs_laser_height: beams per turn, max range (m) and
            the beam plane's height above the frame (m).
    """

    obs_depth_cameras: tuple[str, ...] = ()
    obs_depth_size: Size = (64, 48)
    obs_depth_range: tuple[float, float] = (0.0, 3.0)
    obs_rgb_cameras: tuple[str, ...] = ()
    obs_rgb_size: Size = (64, 64)
    obs_rgb_textures: bool = False
    obs_rgb_shadows: bool = False
    obs_rgb_samples: int = 1
    obs_laser_frame: str | None = None
    obs_laser_beams: int = 360
    obs_laser_range: float = 12.0
    obs_laser_height: float = 0.3

    def __post_init__(self) -> None:
        for name in ("obs_depth_size", "obs_rgb_size"):
            size = getattr(self, name)
            check(min(size) >= 1, f"option {name}={list(size)}: must be >= 1")
        lo, hi = self.obs_depth_range
        check(0 <= lo < hi, f"option obs_depth_range={[lo, hi]}: need 0 <= min < max")
        check(self.obs_rgb_samples >= 1, f"option obs_rgb_samples={self.obs_rgb_samples}: >= 1")
        check(self.obs_laser_beams >= 1, f"option obs_laser_beams={self.obs_laser_beams}: >= 1")
        check(self.obs_laser_range > 0, f"option obs_laser_range={self.obs_laser_range}: > 0")
        for name in ("obs_depth_cameras", "obs_rgb_cameras"):
            cams = getattr(self, name)
            check(len(set(cams)) == len(cams), f"option {name}={list(cams)}: a camera repeats")

    def sensor_specs(self) -> tuple[SensorSpec, ...]:
        """The sensors these options ask for, in observation order."""
        lo, hi = self.obs_depth_range
        w, h = self.obs_depth_size
        specs: list[SensorSpec] = [
            DepthSpec(camera=c, width=w, height=h, min_range_m=lo, max_range_m=hi)
            for c in self.obs_depth_cameras
        ]
        rw, rh = self.obs_rgb_size
        style = RgbStyle(self.obs_rgb_textures, self.obs_rgb_shadows, self.obs_rgb_samples)
        specs += [RgbSpec(camera=c, width=rw, height=rh, style=style) for c in self.obs_rgb_cameras]
        if self.obs_laser_frame is not None:
            specs.append(
                LaserSpec(
                    frame=self.obs_laser_frame,
                    n_beams=self.obs_laser_beams,
                    max_range_m=self.obs_laser_range,
                    height_m=self.obs_laser_height,
                    angle_min=-math.pi,
                )
            )
        return tuple(specs)


def sensor_shapes(specs: tuple[SensorSpec, ...]) -> dict[str, tuple[int, ...]]:
    """Each sensor's observation shape by key: (H, W) depth, (H, W, 3) RGB, (n,) laser."""
    out: dict[str, tuple[int, ...]] = {}
    for s in specs:
        if isinstance(s, LaserSpec):
            out[sensor_key(s)] = (s.n_beams,)
        elif isinstance(s, RgbSpec):
            out[sensor_key(s)] = (s.height, s.width, 3)
        else:
            assert s.width is not None and s.height is not None
            out[sensor_key(s)] = (-(-s.height // s.stride), -(-s.width // s.stride))
    return out


def sensor_obs(q: Quantities, shapes: dict[str, tuple[int, ...]]) -> list[jax.Array]:
    """The sensors' readings, flattened in `shapes` order (for concatenation into obs)."""
    return [jnp.reshape(q.sensors[k], (-1,)).astype(jnp.float32) for k in shapes]


def range_slices(specs: tuple[SensorSpec, ...]) -> tuple[tuple[str, float], ...]:
    """The depth cameras' and lasers' keys with their reading of no return (the max range):
    what depth noise and dropout act on (`RandomizationTargets.range_obs`)."""
    return tuple((sensor_key(s), float(s.max_range_m)) for s in specs if not isinstance(s, RgbSpec))


def observed_cameras(specs: tuple[SensorSpec, ...], model: mujoco.MjModel) -> tuple[int, ...]:
    """Ids of the cameras whose depth or RGB images `specs` observe (what `camera_pos` and
    `camera_rot` move: `RandomizationTargets.cameras`)."""
    cams = {s.camera for s in specs if isinstance(s, DepthSpec | RgbSpec)}
    return tuple(sorted(model.camera(c).id for c in cams))


def rendered_lights(specs: tuple[SensorSpec, ...], model: mujoco.MjModel) -> tuple[int, ...]:
    """Ids of the active lights of `model` when `specs` observe an RGB image, else none (what
    `light` varies: `RandomizationTargets.lights`; depth and lasers see no light)."""
    if not any(isinstance(s, RgbSpec) for s in specs):
        return ()
    return tuple(i for i in range(model.nlight) if model.light_active[i])
