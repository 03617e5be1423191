"""A matrix product whose every row is computed alike at any batch size, on a GPU (Pallas).

XLA hands a batched `x @ w` to a GEMM whose kernel (tiles, split-K) it picks by the batch
size, so a row's last bits depend on how many rows came with it. This kernel fixes the tiles
instead: each program takes `ROWS` rows and up to `MAX_COLS` columns and sums over the inputs
in blocks of `DEPTH`, in one order, whatever the grid. The batch size sets only how many
programs run, so a row's result is the same bits alone or among 65,536, wherever it sits.
Products are IEEE float32 (no TF32).
`fixed_order.dense` uses it for a batch of vectors on a GPU.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from jax.experimental import pallas as pl
from jax.experimental.pallas import triton as pltriton

# Of 17 tile shapes tried for a 3 x 256 MLP at 65,536 rows on an H200, 32 rows x 64 columns
# at depth 16 or 32 were fastest (1.16-1.27 ms a forward pass), against 1.95 ms at 64 x 64 x 32
# and 3.9 ms for the elementwise loop (benchmarks/fixed_order_dense.py; BENCHMARKS.md, issue
# 38). Every shape tried was batch-invariant.
ROWS = 32
DEPTH = 16
MAX_COLS = 64
WARPS = 4


def _padded(n: int, block: int) -> int:
    return -(-n // block) * block


def _cols(n: int) -> int:
    """Columns per program: `MAX_COLS`, or the next power of two >= 16 for a narrow layer."""
    return min(MAX_COLS, max(16, 1 << (n - 1).bit_length()))


def _kernel(x_ref, w_ref, b_ref, o_ref, *, depth_blocks: int) -> None:
    acc = jnp.zeros(o_ref.shape, jnp.float32)
    for k in range(depth_blocks):  # static: one order of the input blocks
        part = pl.ds(k * DEPTH, DEPTH)
        acc += jnp.dot(x_ref[:, part], w_ref[part, :], precision=jax.lax.Precision.HIGHEST)
    o_ref[...] = acc + b_ref[...]


def rows_matmul(x: jax.Array, w: jax.Array, b: jax.Array, *, interpret: bool = False) -> jax.Array:
    """`x @ w + b` for `x` (n, d), `w` (d, m), `b` (m,), float32; `interpret` runs the kernel
    with jax.numpy (for tests off the GPU). The tiles are read when traced."""
    n, d = x.shape
    m = w.shape[1]
    cols = _cols(m)
    rows_p, d_p, m_p = _padded(n, ROWS), _padded(d, DEPTH), _padded(m, cols)
    # zeros in the padding add exactly nothing to a real row's sums
    x = jnp.pad(x.astype(jnp.float32), ((0, rows_p - n), (0, d_p - d)))
    w = jnp.pad(w.astype(jnp.float32), ((0, d_p - d), (0, m_p - m)))
    b = jnp.pad(b.astype(jnp.float32), (0, m_p - m))[None]
    out = pl.pallas_call(
        functools.partial(_kernel, depth_blocks=d_p // DEPTH),
        out_shape=jax.ShapeDtypeStruct((rows_p, m_p), jnp.float32),
        grid=(rows_p // ROWS, m_p // cols),
        in_specs=[
            pl.BlockSpec((ROWS, d_p), lambda i, j: (i, 0)),
            pl.BlockSpec((d_p, cols), lambda i, j: (0, j)),
            pl.BlockSpec((1, cols), lambda i, j: (0, j)),
        ],
        out_specs=pl.BlockSpec((ROWS, cols), lambda i, j: (i, j)),
        interpret=interpret,
        compiler_params=None if interpret else pltriton.CompilerParams(num_warps=WARPS),
        name="rows_matmul",
    )(x, w, b)
    return out[:n, :m]
