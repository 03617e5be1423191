"""The geoms a sensor can hit, chosen once from the model, and casting rays at them in JAX.

`GeomSet.select` applies MuJoCo's `mj_ray` filters at build time (geom groups, static geoms,
invisible geoms, excluded bodies), so the jitted cast only loops over geoms that can be hit.
Geom poses are composed from body poses (`xpos`, `xquat`, indexed by body id as in MuJoCo's
`mjData`) and each geom's fixed offset in its body, so any physics backend that reports body
poses can feed a sensor. Geoms of bodies welded to the world have constant poses, computed
here once.

The cast is written as elementwise arithmetic over a (rays, geoms) grid followed by a minimum
over geoms: XLA fuses it into one loop, and a fixed operation order gives the same bits at any
batch size (so a sensor observation does not change an episode across batch layouts).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable, Sequence

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from openral_mjx.core.errors import ConfigError
from openral_mjx.core.rotations import quat_to_mat, quat_to_mat_np
from openral_mjx.raycast import primitives as prim

_T = mujoco.mjtGeom
_SUPPORTED: dict[int, Callable] = {
    int(_T.mjGEOM_PLANE): prim.plane,
    int(_T.mjGEOM_SPHERE): prim.sphere,
    int(_T.mjGEOM_CAPSULE): prim.capsule,
    int(_T.mjGEOM_ELLIPSOID): prim.ellipsoid,
    int(_T.mjGEOM_CYLINDER): prim.cylinder,
    int(_T.mjGEOM_BOX): prim.box,
}
_SPHERE = int(_T.mjGEOM_SPHERE)
ALL_GROUPS = tuple(range(mujoco.mjNGROUP))
VISIBLE_GROUPS = (0, 1, 2)  # what MuJoCo and MuJoCo-Warp render by default


def mat_vec(m: jax.Array, v: jax.Array) -> jax.Array:
    """m @ v for (..., 3, 3) and (..., 3), in a fixed order."""
    return jnp.stack(
        [
            m[..., i, 0] * v[..., 0] + m[..., i, 1] * v[..., 1] + m[..., i, 2] * v[..., 2]
            for i in range(3)
        ],
        axis=-1,
    )


def mat_mat(a: jax.Array, b: jax.Array) -> jax.Array:
    """a @ b for (..., 3, 3) matrices, in a fixed order."""
    cols = [mat_vec(a, b[..., :, j]) for j in range(3)]
    return jnp.stack(cols, axis=-1)


def transpose(m: jax.Array) -> jax.Array:
    return jnp.swapaxes(m, -1, -2)


def subtree(model: mujoco.MjModel, roots: Iterable[int]) -> set[int]:
    """The bodies `roots` and all their descendants."""
    roots = set(roots)
    out = set()
    for b in range(model.nbody):
        a = b
        while True:
            if a in roots:
                out.add(b)
                break
            if a == 0:
                break
            a = int(model.body_parentid[a])
    return out


def body_ids(model: mujoco.MjModel, names: Sequence[str], what: str) -> list[int]:
    """Body ids of `names`; an unknown name is a `ConfigError` listing the bodies."""
    ids = []
    for name in names:
        i = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
        if i < 0:
            valid = [model.body(b).name for b in range(model.nbody)]
            raise ConfigError(f"{what}: unknown body {name!r}; valid: {', '.join(valid)}")
        ids.append(i)
    return ids


def is_static(model: mujoco.MjModel, body: int) -> bool:
    """Whether a body can never move (welded to the world and not a mocap body)."""
    return int(model.body_weldid[body]) == 0 and int(model.body_mocapid[body]) < 0


def rest_data(model: mujoco.MjModel) -> mujoco.MjData:
    """Kinematics at `qpos0`: exact poses for every static body, geom, site and camera."""
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    mujoco.mj_camlight(model, data)
    return data


def bound_radius(model: mujoco.MjModel, g: int) -> float:
    """Radius of a sphere about geom `g`'s centre that contains it (inf: an unbounded plane)."""
    t, size = int(model.geom_type[g]), model.geom_size[g]
    if t == _T.mjGEOM_PLANE:
        return float(np.hypot(size[0], size[1])) if min(size[:2]) > 0 else np.inf
    if t == _T.mjGEOM_SPHERE:
        return float(size[0])
    if t == _T.mjGEOM_CAPSULE:
        return float(size[0] + size[1])
    if t == _T.mjGEOM_CYLINDER:
        return float(np.hypot(size[0], size[1]))
    if t == _T.mjGEOM_ELLIPSOID:
        return float(max(size))
    return float(np.linalg.norm(size))


def static_bounds(model: mujoco.MjModel) -> tuple[np.ndarray, np.ndarray]:
    """Bounding-sphere centres (ngeom, 3) and radii (ngeom,) of every geom; a geom that can
    move gets radius inf (never culled by its bounds)."""
    data = rest_data(model)
    radius = np.array(
        [
            bound_radius(model, g) if is_static(model, int(model.geom_bodyid[g])) else np.inf
            for g in range(model.ngeom)
        ]
    )
    return data.geom_xpos.copy(), radius


@dataclasses.dataclass(frozen=True)
class _TypeGroup:
    """The selected geoms of one type: sizes and poses in their bodies' frames.

    Static geoms have body 0 (the world, whose pose is the identity) and their world pose as
    the offset.
    """

    kind: int
    geom_ids: np.ndarray  # (G,) int
    body: np.ndarray  # (G,) int
    size: np.ndarray  # (G, 3) float32
    pos: np.ndarray  # (G, 3) float32, in the body frame
    rot: np.ndarray  # (G, 3, 3) float32, in the body frame

    def subset(self, keep: np.ndarray) -> _TypeGroup:
        return dataclasses.replace(
            self,
            geom_ids=self.geom_ids[keep],
            body=self.body[keep],
            size=self.size[keep],
            pos=self.pos[keep],
            rot=self.rot[keep],
        )


class GeomSet:
    """The geoms rays may hit, grouped by type (see module docstring)."""

    def __init__(self, model: mujoco.MjModel, geom_ids: Sequence[int]) -> None:
        geom_ids = np.asarray(sorted(geom_ids), dtype=np.int64)
        bad = [g for g in geom_ids if int(model.geom_type[g]) not in _SUPPORTED]
        if bad:
            names = [model.geom(g).name or f"#{g}" for g in bad]
            kinds = sorted({_T(int(model.geom_type[g])).name for g in bad})
            raise ConfigError(
                f"ray casts support primitive geoms only; geoms {names} are {kinds}: leave them "
                "out with the sensor's geom groups or excluded bodies"
            )
        data = rest_data(model)
        self.model_nbody = model.nbody
        groups = []
        for kind in _SUPPORTED:
            ids = geom_ids[model.geom_type[geom_ids] == kind]
            if ids.size == 0:
                continue
            body = model.geom_bodyid[ids].astype(np.int64)
            pos = model.geom_pos[ids].copy()
            rot = np.stack([quat_to_mat_np(q) for q in model.geom_quat[ids]])
            static = np.array([is_static(model, int(b)) for b in body])
            pos[static] = data.geom_xpos[ids[static]]
            rot[static] = data.geom_xmat[ids[static]].reshape(-1, 3, 3)
            body[static] = 0
            groups.append(
                _TypeGroup(
                    kind,
                    ids,
                    body,
                    model.geom_size[ids].astype(np.float32),
                    pos.astype(np.float32),
                    rot.astype(np.float32),
                )
            )
        self.groups = tuple(groups)

    @classmethod
    def select(
        cls,
        model: mujoco.MjModel,
        *,
        groups: Sequence[int] = VISIBLE_GROUPS,
        static: bool = True,
        exclude_bodies: Iterable[int] = (),
    ) -> GeomSet:
        """The geoms `mj_ray` would consider with these filters (`geomgroup` as group ids,
        `flg_static`, every body in `exclude_bodies` excluded)."""
        bad = [g for g in groups if not 0 <= g < mujoco.mjNGROUP]
        if bad:
            raise ConfigError(f"geom groups {bad} out of range; valid: 0..{mujoco.mjNGROUP - 1}")
        excluded = set(int(b) for b in exclude_bodies)
        keep = []
        for g in range(model.ngeom):
            b = int(model.geom_bodyid[g])
            mat = int(model.geom_matid[g])
            alpha = model.mat_rgba[mat, 3] if mat >= 0 else model.geom_rgba[g, 3]
            group = min(mujoco.mjNGROUP - 1, max(0, int(model.geom_group[g])))
            if (
                b in excluded
                or alpha == 0
                or (not static and int(model.body_weldid[b]) == 0)
                or group not in groups
            ):
                continue
            keep.append(g)
        return cls(model, keep)

    @property
    def geom_ids(self) -> np.ndarray:
        """The selected geoms, by type then id."""
        if not self.groups:
            return np.zeros(0, np.int64)
        return np.concatenate([g.geom_ids for g in self.groups])

    @property
    def bodies(self) -> tuple[int, ...]:
        """Moving bodies whose poses the cast reads."""
        return tuple(sorted({int(b) for g in self.groups for b in g.body if b != 0}))

    def keep(self, predicate: Callable[[int], bool]) -> GeomSet:
        """A copy without the geoms for which `predicate(geom_id)` is False."""
        out = object.__new__(GeomSet)
        out.model_nbody = self.model_nbody
        groups = []
        for g in self.groups:
            mask = np.array([predicate(int(i)) for i in g.geom_ids], bool)
            if mask.any():
                groups.append(g.subset(mask))
        out.groups = tuple(groups)
        return out

    def cast(
        self,
        xpos: jax.Array,
        xquat: jax.Array,
        origin: jax.Array,
        frame: jax.Array,
        dirs: np.ndarray,
    ) -> jax.Array:
        """Distances (R,) from `origin` along unit directions to the nearest selected geom.

        `dirs` (R, 3) are fixed directions in the sensor's frame, whose world rotation is
        `frame` (3, 3); `xpos`/`xquat` are body poses indexed by body id (only `bodies` are
        read). No hit: `inf`.
        """
        dirs = np.asarray(dirs, np.float32)
        body_rot = quat_to_mat(xquat)
        best = jnp.full(dirs.shape[0], jnp.inf, jnp.float32)
        # Sensor directions in the world, for rotation-free tests (spheres).
        world = None
        for g in self.groups:
            rot_b = body_rot[g.body]  # (G, 3, 3); body 0 is the identity
            pos = xpos[g.body] + mat_vec(rot_b, jnp.asarray(g.pos))
            rot = mat_mat(rot_b, jnp.asarray(g.rot))
            w = origin - pos  # (G, 3)
            if g.kind == _SPHERE:
                if world is None:
                    world = [_lin(frame[i], dirs)[:, None] for i in range(3)]
                dist = prim.sphere(g.size[:, 0], [w[:, i] for i in range(3)], world)
            else:
                rt = transpose(rot)
                p = mat_vec(rt, w)
                a = mat_mat(rt, frame)  # sensor frame -> geom frame
                v = [_lin(a[:, i], dirs) for i in range(3)]
                dist = _SUPPORTED[g.kind](g.size, [p[:, i] for i in range(3)], v)
            best = jnp.minimum(best, jnp.min(dist, axis=1))
        return best


def _lin(row: jax.Array, dirs: np.ndarray) -> jax.Array:
    """sum_j row[..., j] * dirs[:, j] as an (R, ...) grid, skipping all-zero direction columns."""
    out = None
    for j in range(3):
        col = dirs[:, j]
        if not np.any(col):
            continue
        c = jnp.asarray(col).reshape((-1,) + (1,) * (row.ndim - 1))
        term = row[..., j] * c
        out = term if out is None else out + term
    if out is None:
        return jnp.zeros((dirs.shape[0], *row.shape[:-1]), row.dtype)
    return out
