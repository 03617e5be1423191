"""`depth_image` / `depth_pointcloud`: a depth camera ray cast through a pinhole model.

One ray per (strided) pixel through the named MJCF camera's live pose. Pixel (u, v) covers
[u, u + 1) x [v, v + 1) of the image (u right, v down) and its ray passes through its centre,
(x, y) = ((u + 0.5 - cx) / fx, (v + 0.5 - cy) / fy) on the plane z = 1 of the camera's optical
frame (+x right, +y down, +z forward; REP-103), so a centred principal point is (W/2, H/2).
By default the intrinsics are the MJCF camera's own (its `fovy`, or its focal length, sensor
size and principal point), scaled to the requested resolution exactly as MuJoCo's and
MuJoCo-Warp's renderers draw it: the ray through a pixel hits what the renderer shows there.

Outputs have fixed shapes under `jit` (the CPU original filtered): depth is the distance along
the optical axis (z), `max_range_m` where a pixel measures nothing (no surface, or one outside
[`min_range_m`, `max_range_m`]), never NaN or inf; points are in the optical frame, zero where
invalid; a validity mask says which pixels measured a surface.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from openral_mjx.core.options import check
from openral_mjx.raycast import mount as mounts
from openral_mjx.raycast.geoms import VISIBLE_GROUPS, GeomSet, body_ids, static_bounds, subtree
from openral_mjx.raycast.mount import JITTER_POS_M, JITTER_ROT_RAD, CameraLocal, moved

# View-culling margin on the image plane's slopes for a camera turned by JITTER_ROT_RAD: a
# turn moves a ray's slope by up to angle * (1 + slope^2), and slopes here reach about 1.
_SLOPE_MARGIN = 2.5 * JITTER_ROT_RAD

Intrinsics = tuple[float, float, float, float]  # fx, fy, cx, cy in pixels


@dataclasses.dataclass(frozen=True)
class DepthSpec:
    """What a depth camera is; `build` resolves it against a model.

    Attributes:
        camera: MJCF camera the depth camera rides on (its live pose; mode `fixed`).
        name: key of its readings (observations, recorded frames); default `depth_CAMERA`.
        width, height: image size in pixels before striding; default the camera's resolution.
        intrinsics: (fx, fy, cx, cy) in pixels at width x height; default the camera's own.
        stride: cast every `stride`-th pixel along both axes (an image of ceil(H/s) x ceil(W/s)).
        min_range_m, max_range_m: depths (along the optical axis) the camera measures.
        groups: geom groups it sees (MuJoCo's `geomgroup`).
        exclude: bodies whose geoms (and their descendants') it does not see.
    """

    camera: str
    name: str | None = None
    width: int | None = None
    height: int | None = None
    intrinsics: Intrinsics | None = None
    stride: int = 1
    min_range_m: float = 0.0
    max_range_m: float = 10.0
    groups: tuple[int, ...] = VISIBLE_GROUPS
    exclude: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        what = f"depth camera {self.key!r}"
        for field in ("width", "height"):
            value = getattr(self, field)
            check(value is None or value >= 1, f"{what}: {field}={value} must be >= 1")
        check(self.stride >= 1, f"{what}: stride={self.stride} must be >= 1")
        check(
            0 <= self.min_range_m < self.max_range_m,
            f"{what}: need 0 <= min_range_m < max_range_m, got {self.min_range_m}, "
            f"{self.max_range_m}",
        )
        if self.intrinsics is not None:
            check(min(self.intrinsics[:2]) > 0, f"{what}: focal lengths {self.intrinsics[:2]} <= 0")

    @property
    def key(self) -> str:
        return self.name or f"depth_{self.camera}"

    def build(self, model: mujoco.MjModel) -> DepthCamera:
        return DepthCamera(model, self)


def camera_intrinsics(model: mujoco.MjModel, cam: int, width: int, height: int) -> Intrinsics:
    """(fx, fy, cx, cy) in pixels of MJCF camera `cam` rendered at width x height.

    As MuJoCo's renderers do: a camera with a sensor size uses its focal length and principal
    point, and MuJoCo's principal point is the offset of the image centre from the optical
    axis, so the axis crosses the image at (W/2 - px, H/2 - py); a camera without one has
    square pixels and its vertical field of view `fovy`, centred. When the image's aspect
    ratio is not the sensor's, the sensor is cropped (centred) to it, keeping square pixels,
    as MuJoCo-Warp's renderer does (MuJoCo's OpenGL renderer stretches it instead).
    """
    sensor_w, sensor_h = (float(x) for x in model.cam_sensorsize[cam])
    if sensor_h == 0:
        fy = height / 2 / np.tan(np.radians(model.cam_fovy[cam]) / 2)
        return float(fy), float(fy), width / 2, height / 2
    focal_x, focal_y, principal_x, principal_y = (float(x) for x in model.cam_intrinsic[cam])
    aspect = width / height
    if aspect > sensor_w / sensor_h:
        sensor_h = sensor_w / aspect
    elif aspect < sensor_w / sensor_h:
        sensor_w = sensor_h * aspect
    sx, sy = width / sensor_w, height / sensor_h  # pixels per metre of sensor
    return focal_x * sx, focal_y * sy, width / 2 - principal_x * sx, height / 2 - principal_y * sy


class DepthCamera:
    """A `DepthSpec` resolved against a model: pixel rays and the geoms they can hit."""

    def __init__(self, model: mujoco.MjModel, spec: DepthSpec) -> None:
        what = f"depth camera {spec.key!r}"
        self.spec = spec
        self.cam_id, self.mount = mounts.camera(model, spec.camera, what)
        self.local = (model.cam_pos[self.cam_id].copy(), model.cam_quat[self.cam_id].copy())
        res = model.cam_resolution[self.cam_id]
        self.width = int(spec.width or res[0])
        self.height = int(spec.height or res[1])
        self.intrinsics = spec.intrinsics or camera_intrinsics(
            model, self.cam_id, self.width, self.height
        )
        fx, fy, cx, cy = self.intrinsics
        us = np.arange(0, self.width, spec.stride)
        vs = np.arange(0, self.height, spec.stride)
        self.shape = (len(vs), len(us))
        x = (us + 0.5 - cx) / fx
        y = (vs + 0.5 - cy) / fy
        grid = np.stack(
            [np.broadcast_to(x[None, :], self.shape), np.broadcast_to(y[:, None], self.shape)],
            axis=-1,
        ).reshape(-1, 2)
        optical = np.concatenate([grid, np.ones((grid.shape[0], 1))], axis=1)
        optical /= np.linalg.norm(optical, axis=1, keepdims=True)
        self.optical_dirs = optical.astype(np.float32)  # (P, 3) unit, optical frame
        # MuJoCo's camera frame: +x right, +y up, looking along -z.
        self.dirs = (optical * np.array([1.0, -1.0, -1.0])).astype(np.float32)
        excluded = subtree(model, body_ids(model, spec.exclude, what)) if spec.exclude else set()
        geoms = GeomSet.select(model, groups=spec.groups, exclude_bodies=excluded)
        if self.mount.static:
            geoms = geoms.keep(self._in_view(model, grid))
        self.geoms = geoms

    def _in_view(self, model: mujoco.MjModel, grid: np.ndarray):
        """A predicate: whether a geom's bounding sphere meets the (static) viewing frustum
        spanned by the cast rays, within range."""
        centre, radius = static_bounds(model)
        # Widened so that a camera moved by at most JITTER_POS_M and turned by at most
        # JITTER_ROT_RAD (a randomised camera) still sees every geom it can hit.
        radius = radius + JITTER_POS_M
        # Geom centres in the optical frame.
        rot = self.mount.rot.astype(np.float64) * np.array([1.0, -1.0, -1.0])
        local = (centre - self.mount.pos) @ rot
        lo, hi = grid.min(axis=0) - _SLOPE_MARGIN, grid.max(axis=0) + _SLOPE_MARGIN
        normals = [  # inward normals of the four side planes through the camera centre
            np.array([1.0, 0.0, -lo[0]]),
            np.array([-1.0, 0.0, hi[0]]),
            np.array([0.0, 1.0, -lo[1]]),
            np.array([0.0, -1.0, hi[1]]),
        ]
        # The longest cast ray that can still be within max_range along the axis.
        reach = self.spec.max_range_m * np.sqrt(
            1 + max(abs(lo[0]), abs(hi[0])) ** 2 + max(abs(lo[1]), abs(hi[1])) ** 2
        )

        def visible(g: int) -> bool:
            c, r = local[g], radius[g]
            if not np.isfinite(r):
                return True
            inside = all(n @ c / np.linalg.norm(n) >= -r for n in normals)
            return bool(inside and c[2] >= -r and np.linalg.norm(c) <= reach + r)

        return visible

    def pose(
        self, xpos: jax.Array, xquat: jax.Array, local: CameraLocal | None = None
    ) -> tuple[jax.Array, jax.Array]:
        """The camera's world position and rotation; with `local` (its `cam_pos`, `cam_quat`
        in this env), moved by the difference from the model's own, in its own frame."""
        pos, rot = self.mount.pose(xpos, xquat)
        if local is None:
            return pos, rot
        return moved(pos, rot, self.local, local)

    @property
    def bodies(self) -> tuple[int, ...]:
        """Moving bodies whose poses the image reads (ids into `xpos`/`xquat`)."""
        extra = () if self.mount.static else (self.mount.body,)
        return tuple(sorted(set(self.geoms.bodies) | set(extra)))


def _cast(
    camera: DepthCamera, xpos: jax.Array, xquat: jax.Array, local: CameraLocal | None = None
) -> tuple[jax.Array, ...]:
    """Per pixel (flat): distance along the ray, depth along the axis, validity."""
    pos, rot = camera.pose(xpos, xquat, local)
    dist = camera.geoms.cast(xpos, xquat, pos, rot, camera.dirs)
    depth = dist * jnp.asarray(camera.optical_dirs[:, 2])
    spec = camera.spec
    valid = (depth >= spec.min_range_m) & (depth <= spec.max_range_m)  # False for inf and NaN
    return dist, depth, valid


def depth_image(
    camera: DepthCamera, xpos: jax.Array, xquat: jax.Array, local: CameraLocal | None = None
) -> tuple[jax.Array, jax.Array]:
    """Depth (H, W) float32 in metres along the optical axis (`max_range_m` where invalid) and
    the validity mask (H, W) bool. Body poses as in `laser_scan`; one env, `vmap` for a batch.
    `local`: this env's camera pose in its body's frame (`cam_pos`, `cam_quat`), where it
    differs from the model's (a randomised camera)."""
    _, depth, valid = _cast(camera, xpos, xquat, local)
    depth = jnp.where(valid, depth, jnp.float32(camera.spec.max_range_m))
    return depth.reshape(camera.shape), valid.reshape(camera.shape)


def depth_pointcloud(
    camera: DepthCamera, xpos: jax.Array, xquat: jax.Array
) -> tuple[jax.Array, jax.Array]:
    """Hit points (H*W, 3) float32 in the camera's optical frame (+x right, +y down, +z
    forward; zero where invalid) and the validity mask (H*W,), pixels in row-major order."""
    dist, _, valid = _cast(camera, xpos, xquat)
    points = dist[:, None] * jnp.asarray(camera.optical_dirs)
    return jnp.where(valid[:, None], points, 0.0), valid
