"""`fixed_order`'s small linear algebra against numpy (float64)."""

from __future__ import annotations

import numpy as np

from openral_mjx.core import fixed_order as fo

RNG = np.random.default_rng(0)


def _spd(n: int) -> np.ndarray:
    a = RNG.normal(size=(n, n))
    return (a @ a.T + n * np.eye(n)).astype(np.float32)


def test_products_and_sums_match_numpy() -> None:
    a = RNG.normal(size=(4, 3, 5)).astype(np.float32)
    b = RNG.normal(size=(4, 5, 2)).astype(np.float32)
    x = RNG.normal(size=(4, 5)).astype(np.float32)
    f64 = lambda v: np.asarray(v, np.float64)  # noqa: E731
    np.testing.assert_allclose(fo.mm(a, b), f64(a) @ f64(b), rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(fo.mv(a, x), np.einsum("kij,kj->ki", f64(a), f64(x)), atol=1e-5)
    np.testing.assert_allclose(fo.mm(a[0], b[0]), f64(a[0]) @ f64(b[0]), atol=1e-5)  # no stack
    np.testing.assert_allclose(fo.total(a), f64(a).sum(0), atol=1e-5)
    np.testing.assert_allclose(fo.dot(x, x), (f64(x) ** 2).sum(-1), rtol=1e-5)


def test_solve_spd_solves_and_inverts() -> None:
    a = _spd(6)
    b = RNG.normal(size=6).astype(np.float32)
    np.testing.assert_allclose(fo.solve_spd(a, b), np.linalg.solve(a, b), rtol=1e-4, atol=1e-5)
    inverse = np.asarray(fo.inv_spd(a), np.float64)
    np.testing.assert_allclose(inverse @ a, np.eye(6), atol=1e-5)


def test_dense_is_the_same_bits_at_any_batch_size_alone_or_with_per_env_weights() -> None:
    """On the CPU: `dense` equals x @ W + b; a batch's first rows are the same bits as a
    smaller batch's (and as a vector alone), and the per-env-weights path agrees too."""
    import jax

    x = RNG.normal(size=(9, 40)).astype(np.float32)
    w = RNG.normal(size=(40, 7)).astype(np.float32)
    b = RNG.normal(size=7).astype(np.float32)
    shared = jax.jit(jax.vmap(fo.dense, in_axes=(0, None, None)))
    out = np.asarray(shared(x, w, b))
    np.testing.assert_allclose(out, np.float64(x) @ w + b, rtol=1e-5, atol=1e-5)
    assert np.array_equal(np.asarray(shared(x[:2], w, b)), out[:2])
    assert np.array_equal(np.asarray(jax.jit(fo.dense)(x[4], w, b)), out[4])
    per_env = jax.jit(jax.vmap(fo.dense))(x, np.repeat(w[None], 9, 0), np.repeat(b[None], 9, 0))
    assert np.array_equal(np.asarray(per_env), out)


def test_the_gpus_fixed_tile_product_pads_and_multiplies_right() -> None:
    """`rows_matmul` (the GPU's path, run by Pallas's interpreter here) against numpy for
    shapes that fill no tile: rows, inputs and outputs are padded and cut back."""
    from openral_mjx.core.batch_invariant import rows_matmul

    for n, d, m in [(3, 39, 256), (130, 256, 4), (64, 32, 64)]:
        x = RNG.normal(size=(n, d)).astype(np.float32)
        w = RNG.normal(size=(d, m)).astype(np.float32)
        b = RNG.normal(size=m).astype(np.float32)
        out = np.asarray(rows_matmul(x, w, b, interpret=True))
        assert out.shape == (n, m)
        np.testing.assert_allclose(out, np.float64(x) @ w + b, rtol=1e-5, atol=2e-5)


def test_a_batch_goes_to_the_fixed_tiles_on_cuda_and_to_the_loop_on_the_cpu() -> None:
    """The platform dispatch, from the lowered programs (no GPU needed to lower for one)."""
    import jax
    import jax.numpy as jnp

    layer = jax.jit(jax.vmap(fo.dense, in_axes=(0, None, None)))
    traced = layer.trace(jnp.zeros((8, 40)), jnp.zeros((40, 7)), jnp.zeros(7))
    cuda = traced.lower(lowering_platforms=("cuda",)).as_text()
    cpu = traced.lower(lowering_platforms=("cpu",)).as_text()
    assert "triton" in cuda.lower() and "while" not in cuda
    assert "triton" not in cpu.lower() and "while" in cpu
