"""Ray-primitive intersection distances, vectorised over rays x geoms, MuJoCo's `mj_ray` rules.

Each function takes a type's geom sizes `(G, 3)` (static) and the rays in every geom's local
frame: origins `p` `(G, 3)` (one origin per sensor, so one per geom) and unit directions `v`
`(R, G, 3)`, each coordinate given as a separate array so that the arithmetic stays elementwise
(XLA fuses it into one loop with the minimum over geoms, and a fixed operation order keeps
results identical at any batch size). The result is the distance `(R, G)` along the ray to the
surface, `inf` where there is none.

Rules follow MuJoCo's `engine_ray.c`: a plane is hit only from its front (+z) side and within
its size (0: unbounded); a ray starting inside a sphere, capsule, ellipsoid, cylinder or box
hits its far side (no back-face culling); a quadratic's roots are taken nearest-first among
those >= 0. The quadratics are solved in a float32-friendly form: the closest approach of the
ray to the centre (or axis) is computed first, so that a small far-away sphere does not lose
its size to cancellation in ``b*b - a*c``.
"""

from __future__ import annotations

from collections.abc import Sequence

import jax.numpy as jnp
import numpy as np

Vec = Sequence[jnp.ndarray]  # three coordinate arrays that broadcast to (R, G)

MINVAL = 1e-15  # MuJoCo's mjMINVAL: directions closer to parallel than this are skipped
INF = jnp.inf


def _first_root(tc: jnp.ndarray, half: jnp.ndarray, ok: jnp.ndarray) -> jnp.ndarray:
    """MuJoCo's `ray_quad` choice: the smaller root if >= 0, else the larger if >= 0."""
    x0, x1 = tc - half, tc + half
    x = jnp.where(x0 >= 0, x0, jnp.where(x1 >= 0, x1, INF))
    return jnp.where(ok, x, INF)


def _roots(tc: jnp.ndarray, h2: jnp.ndarray) -> tuple[jnp.ndarray, jnp.ndarray, jnp.ndarray]:
    """Both roots tc -+ sqrt(h2) and whether they exist (h2 >= 0)."""
    ok = h2 >= 0
    half = jnp.sqrt(jnp.where(ok, h2, 0.0))
    return tc - half, tc + half, ok


def sphere(radius: np.ndarray, w: Vec, d: Vec) -> jnp.ndarray:
    """Sphere of `radius` (G,) centred at the origin; ray origin `w`, unit direction `d`."""
    tc = -(d[0] * w[0] + d[1] * w[1] + d[2] * w[2])  # closest approach along the ray
    q = (w[0] + tc * d[0], w[1] + tc * d[1], w[2] + tc * d[2])
    h2 = radius * radius - (q[0] * q[0] + q[1] * q[1] + q[2] * q[2])
    ok = h2 >= 0
    return _first_root(tc, jnp.sqrt(jnp.where(ok, h2, 0.0)), ok)


def _side(radius: np.ndarray, p: Vec, v: Vec) -> tuple[jnp.ndarray, jnp.ndarray]:
    """The round side of an infinite z-axis cylinder: MuJoCo's root choice, and its z."""
    a = v[0] * v[0] + v[1] * v[1]
    safe_a = jnp.where(a > MINVAL, a, 1.0)
    tc = -(v[0] * p[0] + v[1] * p[1]) / safe_a
    qx, qy = p[0] + tc * v[0], p[1] + tc * v[1]
    h2 = (radius * radius - (qx * qx + qy * qy)) / safe_a
    ok = (h2 >= 0) & (a > MINVAL)
    x = _first_root(tc, jnp.sqrt(jnp.where(ok, h2, 0.0)), ok)
    return x, p[2] + jnp.where(jnp.isfinite(x), x, 0.0) * v[2]


def capsule(size: np.ndarray, p: Vec, v: Vec) -> jnp.ndarray:
    """Capsule along local z: radius size[:, 0], half-length of its cylinder size[:, 1]."""
    r, h = size[:, 0], size[:, 1]
    x, z = _side(r, p, v)
    best = jnp.where(jnp.abs(z) <= h, x, INF)
    for sign in (1.0, -1.0):  # hemispherical caps centred at z = +-h, each its own half
        w = (p[0], p[1], p[2] - sign * h)
        tc = -(v[0] * w[0] + v[1] * w[1] + v[2] * w[2])
        q = (w[0] + tc * v[0], w[1] + tc * v[1], w[2] + tc * v[2])
        x0, x1, ok = _roots(tc, r * r - (q[0] * q[0] + q[1] * q[1] + q[2] * q[2]))
        for root in (x0, x1):
            on_cap = sign * (p[2] + root * v[2]) >= h
            take = ok & (root >= 0) & on_cap & (root < best)
            best = jnp.where(take, root, best)
    return best


def cylinder(size: np.ndarray, p: Vec, v: Vec) -> jnp.ndarray:
    """Cylinder along local z: radius size[:, 0], half-height size[:, 1]."""
    r, h = size[:, 0], size[:, 1]
    x, z = _side(r, p, v)
    best = jnp.where(jnp.abs(z) <= h, x, INF)
    moving = jnp.abs(v[2]) > MINVAL
    vz = jnp.where(moving, v[2], 1.0)
    for sign in (1.0, -1.0):  # flat caps at z = +-h
        sol = (sign * h - p[2]) / vz
        px, py = p[0] + sol * v[0], p[1] + sol * v[1]
        take = moving & (sol >= 0) & (px * px + py * py <= r * r) & (sol < best)
        best = jnp.where(take, sol, best)
    return best


def ellipsoid(size: np.ndarray, p: Vec, v: Vec) -> jnp.ndarray:
    """Ellipsoid with semi-axes size: a unit sphere after scaling each axis."""
    inv = 1.0 / size
    ps = [p[i] * inv[:, i] for i in range(3)]
    vs = [v[i] * inv[:, i] for i in range(3)]
    a = vs[0] * vs[0] + vs[1] * vs[1] + vs[2] * vs[2]
    tc = -(vs[0] * ps[0] + vs[1] * ps[1] + vs[2] * ps[2]) / a
    q = [ps[i] + tc * vs[i] for i in range(3)]
    h2 = (1.0 - (q[0] * q[0] + q[1] * q[1] + q[2] * q[2])) / a
    ok = h2 >= 0
    return _first_root(tc, jnp.sqrt(jnp.where(ok, h2, 0.0)), ok)


def box(size: np.ndarray, p: Vec, v: Vec) -> jnp.ndarray:
    """Box with half-sizes `size`: the slab test (entry face from outside, exit from inside)."""
    near, far = -INF, INF
    for i in range(3):
        moving = jnp.abs(v[i]) > MINVAL
        vi = jnp.where(moving, v[i], 1.0)
        t1 = (-size[:, i] - p[i]) / vi
        t2 = (size[:, i] - p[i]) / vi
        inside = jnp.abs(p[i]) <= size[:, i]
        near = jnp.maximum(
            near, jnp.where(moving, jnp.minimum(t1, t2), jnp.where(inside, -INF, INF))
        )
        far = jnp.minimum(far, jnp.where(moving, jnp.maximum(t1, t2), jnp.where(inside, INF, -INF)))
    hit = (near <= far) & (far >= 0)
    return jnp.where(hit, jnp.where(near >= 0, near, far), INF)


def plane(size: np.ndarray, p: Vec, v: Vec) -> jnp.ndarray:
    """Plane z = 0 facing +z, a rectangle of half-sizes size[:, :2] (<= 0: unbounded)."""
    facing = v[2] <= -MINVAL
    x = -p[2] / jnp.where(facing, v[2], -1.0)
    inside = facing & (x >= 0)
    for i in range(2):
        bounded = size[:, i] > 0
        inside &= ~bounded | (jnp.abs(p[i] + x * v[i]) <= size[:, i])
    return jnp.where(inside, x, INF)
