"""`bench --rays` compares like with like: the sensor, raw `vmap(mjx.ray)` and `mj_multiRay`
cast the very same rays on the same states and measure the same distances (speed is not
tested)."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

from openral_mjx import raycast
from openral_mjx.perf.rays import RayWorkload, clutter_scene, host_states, scene_sensors

TOL = 1e-4  # metres, float32 casts against float64 mj_multiRay


@pytest.fixture(scope="module")
def workloads(box_c):
    datas = host_states(box_c, 2)
    sensors = scene_sensors(box_c, "ee", None)
    small = raycast.DepthSpec("overhead", width=16, height=10).build(box_c.mj_model)
    return {
        "laser": RayWorkload(box_c.mj_model, sensors["laser360"], datas),
        "depth": RayWorkload(box_c.mj_model, small, datas),
    }


def _distances(work: RayWorkload) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per env and ray: the sensor's distance along the ray (inf: nothing in range), raw
    mjx.ray's and mj_multiRay's (inf: no hit)."""
    fn, args = work.raw_fn()
    raw = np.asarray(fn(*args), np.float64)
    _, c = work.multiray(threads=2)
    out = np.asarray(work.sensor_fn()(work.xpos, work.xquat), np.float64)
    if isinstance(work.sensor, raycast.Laser):
        sensor = np.where(out < work.sensor.spec.max_range_m, out, np.inf)
    else:
        z = work.sensor.optical_dirs[:, 2].astype(np.float64)
        depth = out.reshape(work.n, -1)
        sensor = np.where(depth < work.sensor.spec.max_range_m, depth / z, np.inf)
    return sensor, np.where(raw < 0, np.inf, raw), np.where(c < 0, np.inf, c)


@pytest.mark.parametrize("name", ["laser", "depth"])
def test_the_three_casts_measure_the_same_rays(workloads, name):
    work = workloads[name]
    sensor, raw, c = _distances(work)
    limit = work.sensor.spec.max_range_m
    for other in (raw, c):
        other = np.where(other < limit, other, np.inf)
        np.testing.assert_array_equal(np.isinf(sensor), np.isinf(other))
        hit = np.isfinite(sensor)
        assert hit.mean() > 0.2
        np.testing.assert_allclose(sensor[hit], other[hit], atol=TOL)


def test_the_geom_count_sweep_scene():
    model, datas = clutter_scene(12, 3)
    assert model.ngeom == 12 and len({id(d) for d in datas}) == 3
    cam = raycast.DepthSpec("top", width=16, height=12).build(model)
    work = RayWorkload(model, cam, datas)
    assert work.xpos.shape == (3, model.nbody, 3) and work.xpos.dtype == jnp.float32
    sensor, raw, c = _distances(work)
    np.testing.assert_array_equal(sensor, sensor[:1].repeat(3, axis=0))
    for other in (raw, c):
        np.testing.assert_allclose(sensor, other, atol=TOL)
