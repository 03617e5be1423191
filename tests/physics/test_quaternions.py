"""Rotation matrix -> quaternion conversions against their references: MuJoCo's `mju_mat2Quat`
(the geom orientations every backend reports) and scipy's `Rotation.as_quat` (the quaternion
convention MetaWorld observes for several tasks, which the mirror reproduces)."""

from __future__ import annotations

import jax
import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from openral_mjx.benchmarks.metaworld.mirror.task import matrix_quat
from openral_mjx.physics.base import mat_to_quat


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
