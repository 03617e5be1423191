"""`core.rotations` against MuJoCo's own conversions (`mju_mat2Quat`, `mju_quat2Mat`,
`mju_mulQuat`; the geom orientations every backend reports), and the mirror's quaternions
against scipy's `Rotation.as_quat` (the convention MetaWorld observes for several tasks)."""

from __future__ import annotations

import jax
import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from openral_mjx.benchmarks.metaworld.mirror.task import matrix_quat
from openral_mjx.core.rotations import (
    mat_to_quat,
    quat_axis_z,
    quat_mul,
    quat_to_mat,
    quat_to_mat_np,
    rotate_inverse,
)


def rotations() -> np.ndarray:
    """Random rotations plus the cases where each of Shepperd's four branches wins (near 180
    degrees about x, y and z, and the identity)."""
    quats = Rotation.random(200, random_state=0).as_quat()  # x, y, z, w
    special = [[1, 0, 0, 0.01], [0, 1, 0, 0.02], [0, 0, 1, 0.03], [0, 0, 0, 1], [1, 1, 0, 0]]
    quats = np.concatenate([quats, np.asarray(special, float)])
    return Rotation.from_quat(quats).as_matrix()


def test_mat_to_quat_matches_mujoco():
    mats = rotations()
    ours = np.asarray(jax.jit(mat_to_quat)(mats.astype(np.float32)))
    for m, q in zip(mats, ours, strict=True):
        ref = np.zeros(4)
        mujoco.mju_mat2Quat(ref, m.reshape(-1))
        ref = ref if ref[0] >= 0 else -ref
        np.testing.assert_allclose(q, ref, atol=2e-6)


def test_matrix_quat_matches_scipy():
    mats = rotations()
    wxyz = np.asarray(jax.jit(mat_to_quat)(mats.astype(np.float32)))
    ours = np.asarray(jax.jit(jax.vmap(matrix_quat))(wxyz))
    ref = Rotation.from_matrix(mats).as_quat()  # scipy's sign, not canonicalised
    np.testing.assert_allclose(ours, ref, atol=2e-6)


def test_quaternion_to_matrix_axis_and_inverse_rotation_match_mujoco():
    quats = Rotation.random(50, random_state=1).as_quat()[:, [3, 0, 1, 2]]  # w, x, y, z
    vecs = np.random.default_rng(2).normal(size=(50, 3))
    mats = np.asarray(jax.jit(quat_to_mat)(quats.astype(np.float32)))
    axes = np.asarray(jax.jit(jax.vmap(quat_axis_z))(quats.astype(np.float32)))
    local = np.asarray(jax.jit(jax.vmap(rotate_inverse))(quats.astype(np.float32), vecs))
    for q, v, m, axis, lv in zip(quats, vecs, mats, axes, local, strict=True):
        ref = np.zeros(9)
        mujoco.mju_quat2Mat(ref, q)
        ref = ref.reshape(3, 3)
        np.testing.assert_array_equal(quat_to_mat_np(q), ref)
        np.testing.assert_allclose(m, ref, atol=2e-6)
        np.testing.assert_allclose(axis, ref[:, 2], atol=2e-6)
        back = np.zeros(3)
        mujoco.mju_mulMatTVec3(back, ref.reshape(-1), v)
        np.testing.assert_allclose(lv, back, atol=1e-5)


def test_quat_mul_matches_mujoco():
    a = Rotation.random(50, random_state=3).as_quat()[:, [3, 0, 1, 2]]
    b = Rotation.random(50, random_state=4).as_quat()[:, [3, 0, 1, 2]]
    ours = np.asarray(jax.jit(quat_mul)(a.astype(np.float32), b.astype(np.float32)))
    for x, y, q in zip(a, b, ours, strict=True):
        ref = np.zeros(4)
        mujoco.mju_mulQuat(ref, x, y)
        np.testing.assert_allclose(q, ref, atol=2e-6)
