"""Small-vector linear algebra with a fixed order of floating-point operations.

XLA's CPU backend chooses how to vectorise reductions (and so their summation order) from the
batch shape, so `jnp.dot`/`jnp.linalg.norm`/`jnp.linalg.solve` on a vmapped env can differ in
the last bit between batch sizes, and contact dynamics amplify that into different episodes.
These helpers unroll the arithmetic over the (small, static) vector length into elementwise
operations in a fixed order, which XLA evaluates identically at any batch size: a seed gives
a bit-identical episode whether it runs alone or among thousands.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from openral_mjx.core.batch_invariant import rows_matmul


def dot(a: jax.Array, b: jax.Array) -> jax.Array:
    """Inner product along the last axis."""
    out = a[..., 0] * b[..., 0]
    for i in range(1, a.shape[-1]):
        out = out + a[..., i] * b[..., i]
    return out


def cross(a: jax.Array, b: jax.Array) -> jax.Array:
    """Cross product of 3-vectors."""
    return jnp.stack(
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    )


def norm(x: jax.Array) -> jax.Array:
    """Euclidean norm along the last axis."""
    return jnp.sqrt(dot(x, x))


def matmul(a: jax.Array, b: jax.Array) -> jax.Array:
    """(m, k) @ (k, n) or (m, k) @ (k,)."""
    if b.ndim == 1:
        return jnp.stack([dot(a[i], b) for i in range(a.shape[0])])
    return jnp.stack(
        [jnp.stack([dot(a[i], b[:, j]) for j in range(b.shape[1])]) for i in range(a.shape[0])]
    )


def mm(a: jax.Array, b: jax.Array) -> jax.Array:
    """(..., m, k) @ (..., k, n), the leading axes broadcast: `matmul` for stacks of
    matrices, one broadcast multiply-add per k."""
    out = a[..., :, 0:1] * b[..., 0:1, :]
    for i in range(1, a.shape[-1]):
        out = out + a[..., :, i : i + 1] * b[..., i : i + 1, :]
    return out


def mv(a: jax.Array, x: jax.Array) -> jax.Array:
    """(..., m, k) @ (..., k), the leading axes broadcast."""
    out = a[..., 0] * x[..., None, 0]
    for i in range(1, a.shape[-1]):
        out = out + a[..., i] * x[..., None, i]
    return out


def total(x: jax.Array) -> jax.Array:
    """The sum over the first axis."""
    out = x[0]
    for i in range(1, x.shape[0]):
        out = out + x[i]
    return out


def solve_spd(a: jax.Array, b: jax.Array) -> jax.Array:
    """Solve `a x = b` for a small symmetric positive-definite `a` (unrolled Cholesky); `b`
    (n,) or (n, r)."""
    n = a.shape[0]
    chol = [[None] * n for _ in range(n)]
    for j in range(n):
        s = a[j, j]
        for k in range(j):
            s = s - chol[j][k] * chol[j][k]
        chol[j][j] = jnp.sqrt(s)
        for i in range(j + 1, n):
            s = a[i, j]
            for k in range(j):
                s = s - chol[i][k] * chol[j][k]
            chol[i][j] = s / chol[j][j]
    y = [None] * n
    for i in range(n):
        s = b[i]
        for k in range(i):
            s = s - chol[i][k] * y[k]
        y[i] = s / chol[i][i]
    x = [None] * n
    for i in reversed(range(n)):
        s = y[i]
        for k in range(i + 1, n):
            s = s - chol[k][i] * x[k]
        x[i] = s / chol[i][i]
    return jnp.stack(x)


def _loop(x: jax.Array, kernel: jax.Array, bias: jax.Array) -> jax.Array:
    """One vector through the layer as a loop of elementwise multiply-adds over `x`'s axis
    (8 per trip: the fastest on the CPU; on a GPU every trip is a kernel over the batch)."""

    def add(i: jax.Array, acc: jax.Array) -> jax.Array:
        return acc + x[i] * kernel[i]

    return jax.lax.fori_loop(1, kernel.shape[0], add, bias + x[0] * kernel[0], unroll=8)


# A batch of vectors (n, d) through the layer by the loop, one vector at a time.
loop_rows = jax.vmap(_loop, in_axes=(0, None, None))


def _rows(x: jax.Array, kernel: jax.Array, bias: jax.Array) -> jax.Array:
    """A batch of vectors (n, d) through the layer: the loop on the CPU; on an NVIDIA GPU the
    fixed-tile product of `batch_invariant` (the loop took ~4 ms a step at 65,536 envs for a
    3 x 256 MLP, a third of that here; issue 38)."""
    return jax.lax.platform_dependent(
        x,
        kernel,
        bias,
        cuda=rows_matmul,
        default=loop_rows,  # the CPU, and any untried platform
    )


@jax.custom_batching.custom_vmap
def dense(x: jax.Array, kernel: jax.Array, bias: jax.Array) -> jax.Array:
    """`x @ kernel + bias` for one input vector `x` (d,), each output summed in a fixed order.

    A vmapped `x @ kernel` is a matrix product whose kernel XLA picks by batch size (on the
    CPU, rows differ in the last bit below ~64 rows), so a learned policy's action, and its
    episode, would depend on the batch. Here the sums' order is fixed: on the CPU by a loop of
    elementwise multiply-adds over `d` (about twice the product's cost), on a GPU by a product
    with fixed tiles (`batch_invariant.rows_matmul`). Under `vmap` the batch goes to either
    whole; a vector alone takes the same path as a batch of one.
    """
    return _rows(x[None], kernel, bias)[0]


@dense.def_vmap
def _dense_batched(
    axis_size: int, in_batched: list[bool], x: jax.Array, kernel: jax.Array, bias: jax.Array
) -> tuple[jax.Array, bool]:
    x_batched, kernel_batched, bias_batched = in_batched
    if kernel_batched or bias_batched:  # weights per env (no shared matrix): the loop per env
        axes = tuple(0 if b else None for b in in_batched)
        return jax.vmap(_loop, in_axes=axes, axis_size=axis_size)(x, kernel, bias), True
    if not x_batched:
        return dense(x, kernel, bias), False
    return _rows(x, kernel, bias), True


def inv_spd(a: jax.Array) -> jax.Array:
    """The inverse of a small symmetric positive-definite `a` (`solve_spd` of the identity)."""
    return solve_spd(a, jnp.eye(a.shape[0], dtype=a.dtype))
