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
