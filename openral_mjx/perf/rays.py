"""`python -m openral_mjx.bench --rays`: ray-cast sensor throughput against its ceilings.

Per batch size N, on the same scene and the same N states (the scene's reset states, poses
from MuJoCo C), measured side by side in rays/s:

* sensors: `raycast.laser_scan` (360 beams from a moving site, the robot excluded) and
  `raycast.depth_image` (64x48 and 128x96 through the scene's first camera), `jit(vmap)`;
* raw: `vmap(vmap(mjx.ray))` casting the very same rays (same origins, directions, geom groups
  and excluded bodies) on an `mjx.Data` holding the same geom poses;
* MuJoCo C: `mujoco.mj_multiRay` for every env on all cores (a thread pool over envs; the
  bindings release the GIL).

A second table measures how the depth camera's cost grows with the number of geoms: a floor
and G - 1 free boxes, capsules and spheres scattered under a static camera.

Pick a scene whose laser has something to hit: in `so101_box` the end-effector's beams meet
the arena walls, on `tabletop_push`'s open table they mostly hit nothing (which flatters
`mj_multiRay`, whose bounding-sphere culling skips misses early).

Ratios (sensor / raw, sensor / C) transfer between machines; absolute numbers count only with
the device named. Device timings: one warm-up call, then the median of `--repeats` calls.
"""

from __future__ import annotations

import copy
import statistics
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from openral_mjx import raycast
from openral_mjx.physics.mjx_backend import mjx
from openral_mjx.raycast.geoms import subtree
from openral_mjx.runner import seed_keys

DEPTH_SIZES = ((64, 48), (128, 96))
LASER_BEAMS = 360


def time_device(fn: Callable[..., Any], *args: Any, repeats: int) -> tuple[float, float]:
    """(compile + first call s, median s of `repeats` further calls) of a jitted function."""
    t = time.perf_counter()
    jax.block_until_ready(fn(*args))
    first = time.perf_counter() - t
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        jax.block_until_ready(fn(*args))
        times.append(time.perf_counter() - t)
    return first, statistics.median(times)


def host_states(scene, n: int) -> list[mujoco.MjData]:
    """MuJoCo C data of the scene's reset states for seeds 0..n-1 (kinematics evaluated)."""
    with jax.default_device(jax.devices("cpu")[0]):
        keys = seed_keys(jnp.arange(n))[0]
        qpos = np.asarray(jax.jit(jax.vmap(scene.reset))(keys).physics.quantities.qpos)
    model = scene.mj_model
    out = []
    for q in qpos:
        d = mujoco.MjData(model)
        d.qpos[:] = q
        mujoco.mj_kinematics(model, d)
        mujoco.mj_camlight(model, d)
        out.append(d)
    return out


class RayWorkload:
    """One sensor's rays on N states: its world origins and directions per env."""

    def __init__(self, model: mujoco.MjModel, sensor: Any, datas: list[mujoco.MjData]) -> None:
        self.model, self.sensor = model, sensor
        self.xpos = jnp.asarray(np.stack([d.xpos for d in datas]), jnp.float32)
        self.xquat = jnp.asarray(np.stack([d.xquat for d in datas]), jnp.float32)
        with jax.default_device(jax.devices("cpu")[0]):
            pos, rot = jax.vmap(sensor.mount.pose)(
                np.stack([d.xpos for d in datas]), np.stack([d.xquat for d in datas])
            )
        pos, rot = np.asarray(pos, np.float64), np.asarray(rot, np.float64)
        if isinstance(sensor, raycast.Laser):
            self.origins = pos + np.array([0.0, 0.0, sensor.spec.height_m])
            a = np.arctan2(rot[:, 1, 0], rot[:, 0, 0])[:, None] + sensor.angles.astype(np.float64)
            self.dirs = np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], axis=-1)
        else:
            self.origins = pos
            self.dirs = np.einsum("rj,nij->nri", sensor.dirs.astype(np.float64), rot)
        self.datas = datas
        self.n, self.rays = len(datas), self.dirs.shape[1]
        mask = np.zeros(mujoco.mjNGROUP, bool)
        mask[list(sensor.spec.groups)] = True
        self.groups = mask
        # The bodies the sensor excludes (a laser's robot), passed on to the references.
        self.excluded: list[int] = []
        if isinstance(sensor, raycast.Laser) and sensor.spec.exclude is None:
            root = sensor.mount.root
            self.excluded = sorted(subtree(model, [root])) if root else []

    def sensor_fn(self) -> Callable[[jax.Array, jax.Array], jax.Array]:
        s = self.sensor
        if isinstance(s, raycast.Laser):
            return jax.jit(jax.vmap(lambda p, q: raycast.laser_scan(s, p, q)))
        return jax.jit(jax.vmap(lambda p, q: raycast.depth_image(s, p, q)[0]))

    def raw_fn(self) -> tuple[Callable[..., jax.Array], tuple[jax.Array, ...]]:
        """`vmap(vmap(mjx.ray))` on the same rays, and its arguments (device arrays)."""
        mx = mjx.put_model(self.model)
        d0 = mjx.make_data(mx)
        groups = tuple(int(g) for g in self.groups)
        exclude = self.excluded or -1

        def env(gpos, gmat, origin, dirs):
            d = d0.replace(geom_xpos=gpos, geom_xmat=gmat)
            return jax.vmap(lambda v: mjx.ray(mx, d, origin, v, groups, True, exclude)[0])(dirs)

        args = (
            jnp.asarray(np.stack([d.geom_xpos for d in self.datas]), jnp.float32),
            jnp.asarray(np.stack([d.geom_xmat.reshape(-1, 3, 3) for d in self.datas]), jnp.float32),
            jnp.asarray(self.origins, jnp.float32),
            jnp.asarray(self.dirs, jnp.float32),
        )
        return jax.jit(jax.vmap(env)), args

    def multiray(self, threads: int) -> tuple[float, np.ndarray]:
        """Seconds for `mj_multiRay` to cast every env's rays, envs spread over `threads`, and
        the distances (N, rays), -1 where a ray hits nothing."""
        geomgroup = self.groups.astype(np.uint8)
        exclude = self.excluded[0] if len(self.excluded) == 1 else -1
        model = self.model
        if len(self.excluded) > 1:  # mj_multiRay excludes one body: hide the others' geoms
            model = copy.copy(self.model)
            for g in range(model.ngeom):
                if int(model.geom_bodyid[g]) in self.excluded:
                    model.geom_matid[g], model.geom_rgba[g, 3] = -1, 0.0

        dist = np.zeros((self.n, self.rays))

        def work(envs: range) -> None:
            geom = np.zeros(self.rays, np.int32)
            for i in envs:
                vec = np.ascontiguousarray(self.dirs[i]).reshape(-1)
                mujoco.mj_multiRay(
                    model, self.datas[i], self.origins[i], vec, geomgroup, 1, exclude,
                    geom, dist[i], None, self.rays, mujoco.mjMAXVAL,
                )  # fmt: skip

        chunks = [range(k, self.n, threads) for k in range(threads)]
        with ThreadPoolExecutor(threads) as pool:
            t = time.perf_counter()
            list(pool.map(work, chunks))
            return time.perf_counter() - t, dist


def scene_sensors(scene, laser_frame: str, camera: str | None) -> dict[str, Any]:
    """The benchmarked sensors of a scene, by row name."""
    model = scene.mj_model
    camera = camera or model.camera(0).name
    out: dict[str, Any] = {
        f"laser{LASER_BEAMS}": raycast.LaserSpec(
            frame=laser_frame, n_beams=LASER_BEAMS, height_m=0.0
        ).build(model)
    }
    for w, h in DEPTH_SIZES:
        out[f"depth{w}x{h}"] = raycast.DepthSpec(camera, width=w, height=h).build(model)
    return out


def clutter_scene(
    n_geoms: int, n: int, seed: int = 0
) -> tuple[mujoco.MjModel, list[mujoco.MjData]]:
    """A floor and `n_geoms - 1` free primitives under a static camera; `n` copies of one
    state (each env its own `MjData`: `mj_multiRay` allocates on the data's stack)."""
    rng = np.random.default_rng(seed)
    spec = mujoco.MjSpec()
    spec.add_material(name="grey", rgba=[0.5, 0.5, 0.5, 1])
    w = spec.worldbody
    w.add_geom(type=mujoco.mjtGeom.mjGEOM_PLANE, size=[2, 2, 0.1], material="grey")
    w.add_camera(name="top", pos=[0, 0, 2.0])
    kinds = (mujoco.mjtGeom.mjGEOM_BOX, mujoco.mjtGeom.mjGEOM_CAPSULE, mujoco.mjtGeom.mjGEOM_SPHERE)
    for i in range(n_geoms - 1):
        b = w.add_body(pos=[*rng.uniform(-0.8, 0.8, 2), rng.uniform(0.05, 0.5)])
        b.add_freejoint()
        b.add_geom(type=kinds[i % 3], size=[0.05, 0.04, 0.03], material="grey")
    model = spec.compile()
    d = mujoco.MjData(model)
    mujoco.mj_kinematics(model, d)
    mujoco.mj_camlight(model, d)
    return model, [copy.copy(d) for _ in range(n)]


def _rays_per_s(
    total: int, fn: Callable[..., Any], *args: Any, repeats: int
) -> tuple[float | None, float | None]:
    """(compile + first call s, rays/s) of a device function casting `total` rays; (None,
    None) where the device runs out of memory (the row says so, the run goes on)."""
    try:
        first, median = time_device(fn, *args, repeats=repeats)
    except jax.errors.JaxRuntimeError as e:
        if "RESOURCE_EXHAUSTED" not in str(e):
            raise
        return None, None
    return first, total / median


def _ratio(a: float | None, b: float | None) -> float | None:
    return None if a is None or b is None else a / b


def measure(work: RayWorkload, threads: int, repeats: int) -> dict:
    """One row: sensor, raw and MuJoCo C rays/s on a workload (None: out of device memory)."""
    total = work.n * work.rays
    row: dict[str, Any] = {
        "n": work.n,
        "rays_per_env": work.rays,
        "geoms": len(work.sensor.geoms.geom_ids),
    }
    row["sensor_compile_s"], row["sensor_rays_per_s"] = _rays_per_s(
        total, work.sensor_fn(), work.xpos, work.xquat, repeats=repeats
    )
    fn, args = work.raw_fn()
    row["raw_compile_s"], row["raw_rays_per_s"] = _rays_per_s(total, fn, *args, repeats=repeats)
    row["sensor_over_raw"] = _ratio(row["sensor_rays_per_s"], row["raw_rays_per_s"])
    row["c_threads"] = threads
    row["c_rays_per_s"] = total / work.multiray(threads)[0]
    row["sensor_over_c"] = _ratio(row["sensor_rays_per_s"], row["c_rays_per_s"])
    return row


def run_rays(
    scene,
    ns: tuple[int, ...],
    *,
    laser_frame: str,
    camera: str | None,
    geom_counts: tuple[int, ...],
    threads: int,
    repeats: int,
    log: Callable,
) -> dict:
    """Every row of the `--rays` benchmark (see module docstring)."""
    sensors = scene_sensors(scene, laser_frame, camera)
    rows = []
    for n in ns:
        datas = host_states(scene, n)
        for name, sensor in sensors.items():
            row = {
                "sensor": name,
                **measure(RayWorkload(scene.mj_model, sensor, datas), threads, repeats),
            }
            rows.append(row)
            log(_line(row))
    sweep = []
    n = min(ns)
    for g in geom_counts:
        model, datas = clutter_scene(g, n)
        cam = raycast.DepthSpec("top", width=64, height=48).build(model)
        row = {
            "sensor": "depth64x48",
            **measure(RayWorkload(model, cam, datas), threads, repeats),
        }
        row["scene_geoms"] = g
        sweep.append(row)
        log(f"geoms={g:>3}: " + _line(row))
    return {"rows": rows, "geom_sweep": sweep}


def _line(row: dict) -> str:
    def m(x: float | None) -> str:
        return "      OOM" if x is None else f"{x / 1e6:>9,.1f}"

    def r(x: float | None, digits: int) -> str:
        return "-" if x is None else f"{x:.{digits}f}"

    return (
        f"N={row['n']:>6} {row['sensor']:<11} sensor {m(row['sensor_rays_per_s'])} M"
        f"  raw mjx.ray {m(row['raw_rays_per_s'])} M  sensor/raw {r(row['sensor_over_raw'], 2)}"
        f"  mj_multiRay({row['c_threads']} thr) {m(row['c_rays_per_s'])} M"
        f"  sensor/C {r(row['sensor_over_c'], 1)}  rays/s"
    )
