"""A LIBERO task's model and facts for the mirror: exported once from LIBERO, then cached.

LIBERO (hf-libero, robosuite 1.4, mujoco 3.8) cannot share this environment, so its task
construction runs in the ``lerobot-libero`` worker environment (`export`), and what it returns
is kept under ``~/.cache/openral_mjx/libero_mjx/<suite>/<index>/`` (``OPENRAL_MJX_LIBERO_MODELS``
moves it): the composed MJCF, the body inertials robosuite's compile gave, the shipped initial
states and the controller's constants. Later runs read the cache and start no worker.

`physics_spec` turns the MJCF into the model the mirror simulates: visual-only geoms and the
assets only they use are dropped (LIBERO's visual meshes hold 0.6-1.1 M vertices against 7 k
for collision), every body's inertial is pinned to the exported one, so the dynamics do not
depend on how our MuJoCo infers inertia from what is left, and every body's pose to the one
LIBERO's reset writes (its fixtures: cabinets, stoves, racks are placed that way).
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import dataclasses
import functools
import json
import os
import shutil
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from openral_mjx.core.errors import ConfigError
from openral_mjx.core.files import atomic_path
from openral_mjx.host.envs import ensure_env, envs_root
from openral_mjx.host.pool import RemoteError, Worker, WorkerFailure

ENV = "lerobot-libero"
FACTORY = "openral_mjx.benchmarks.libero.export:TaskExport"
TIMEOUT_S = 900.0
FORMAT = 7  # bump when `TaskExport.model`'s content changes: older caches are rebuilt


def models_root() -> Path:
    return Path(os.environ.get("OPENRAL_MJX_LIBERO_MODELS", envs_root().parent / "libero_mjx"))


@dataclasses.dataclass(frozen=True)
class TaskModel:
    """One task's export (see `openral_mjx.benchmarks.libero.export`)."""

    task: str
    xml: str
    arrays: dict[str, np.ndarray]
    meta: dict[str, Any]

    @property
    def init_states(self) -> np.ndarray:
        return self.arrays["init_states"]

    @property
    def goal(self) -> list[dict[str, Any]]:
        """The BDDL goal's atoms (all must hold), as `TaskExport.goal` describes them."""
        return list(self.meta["goal"])


def _task_dir(task: str) -> Path:
    suite, _, index = task.partition("/")
    return models_root() / suite / index


def _read(task: str) -> TaskModel | None:
    d = _task_dir(task)
    try:
        meta = json.loads((d / "meta.json").read_text())
        if meta.get("format") != FORMAT:
            return None
        with np.load(d / "arrays.npz") as z:
            arrays = {k: z[k] for k in z.files}
        return TaskModel(task, (d / "model.xml").read_text(), arrays, meta)
    except (OSError, ValueError, KeyError):
        return None


@contextlib.contextmanager
def task_worker(task: str, image_size: int | None = None) -> Iterator[tuple[Worker, Path]]:
    """A worker holding LIBERO's `TaskExport` for `task` (``suite/index``; its cameras at
    `image_size`, if given), and its log; closed on exit."""
    log = Path(tempfile.mkdtemp(prefix="openral_mjx_libero_")) / "worker.log"
    worker = Worker(ensure_env(ENV), {"MUJOCO_GL": "egl"}, log, name=f"libero {task}")
    kwargs = {"task": task, **({"image_size": image_size} if image_size else {})}
    try:
        worker.call({"op": "init", "factory": FACTORY, "kwargs": kwargs}, TIMEOUT_S)
        yield worker, log
    finally:
        worker.close()


def _say(line: str) -> None:
    """A status line on stderr for the one-time work in LIBERO's worker (seconds to minutes)."""
    print(f"libero_mjx: {line}", file=sys.stderr, flush=True)


def _export(task: str) -> TaskModel:
    """Run LIBERO's task construction in a worker and cache what it returns."""
    _say(f"exporting LIBERO task {task} in LIBERO's worker, once (~20 s; kept in {models_root()})")
    log = None
    try:
        with task_worker(task) as (worker, log):
            out = worker.call({"op": "call", "method": "model", "kwargs": {}}, TIMEOUT_S)
            for method in ("goal", "observation_substep"):
                msg = {"op": "call", "method": method, "kwargs": {}}
                out[method] = worker.call(msg, TIMEOUT_S)
            msg = {"op": "call", "method": "fixture_poses", "kwargs": {}}
            out.update(worker.call(msg, TIMEOUT_S))
    except (RemoteError, WorkerFailure) as e:
        raise ConfigError(f"exporting LIBERO task {task!r} failed: {e} (log: {log})") from None
    arrays = {k: np.asarray(v) for k, v in out.items() if isinstance(v, np.ndarray)}
    meta = {k: v for k, v in out.items() if k != "xml" and not isinstance(v, np.ndarray)}
    meta["format"] = FORMAT
    d = _task_dir(task)
    d.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=d.parent, prefix=f".{d.name}."))
    (tmp / "model.xml").write_text(out["xml"])
    np.savez(tmp / "arrays.npz", **arrays)
    (tmp / "meta.json").write_text(json.dumps(meta, indent=1, default=_plain))
    for name in ("model.xml", "arrays.npz", "meta.json"):  # meta.json last: it marks it whole
        os.replace(tmp / name, d / name)
    tmp.rmdir()
    return _read(task) or TaskModel(task, out["xml"], arrays, meta)


def _plain(value: Any) -> Any:
    """numpy values in the export's JSON part as plain lists and numbers."""
    if isinstance(value, np.ndarray | np.generic):
        return value.tolist()
    raise TypeError(f"cannot store {type(value).__name__} in a LIBERO export")


@functools.cache
def load_task(task: str) -> TaskModel:
    """Task ``suite/index``'s export, from the cache or exported now (about 20 s)."""
    return _read(task) or _export(task)


SAMPLED_BLOCK = 32  # seeds drawn per worker call (~2.5 s each on one core): a progress step
SAMPLED_PER_SEED = ("states", "fixture_pos", "fixture_quat")
# bump when `TaskExport.sampled_states`'s draw changes: older draws are drawn again (2: LIBERO's
# full reset per seed; 1, unmarked, re-ran its placement and misplaced objects on fixtures)
SAMPLED_FORMAT = 2


def _read_sampled(path: Path) -> dict[str, np.ndarray] | None:
    try:
        with np.load(path) as z:
            arrays = {k: z[k] for k in z.files}
    except (OSError, ValueError):
        return None
    current = int(arrays.get("format", -1)) == FORMAT
    return arrays if current and int(arrays.get("sampled_format", 1)) == SAMPLED_FORMAT else None


def load_sampled(task: str, n: int) -> dict[str, np.ndarray]:
    """The mass-seed protocol's first `n` initial states of task ``suite/index``: per seed
    the flattened ``[time, qpos, qvel]`` state (``states``) and the poses of the bodies
    LIBERO's reset places without a joint (``fixture_ids`` in the export's body order,
    ``fixture_pos``, ``fixture_quat``), as `TaskExport.sampled_states` draws them. Kept in the
    export cache (``sampled.npz``) and extended in LIBERO's worker where it holds fewer, a
    status line after each block of `SAMPLED_BLOCK` seeds. The blocks are drawn in one
    worker per core (each draw is LIBERO's full reset: ~2.5 s on one core) and kept in seed
    order as they complete, so an interrupted draw keeps a prefix."""
    load_task(task)  # the task's own export first: its format marks this file's too
    path = _task_dir(task) / "sampled.npz"
    have = _read_sampled(path)
    count = 0 if have is None else len(have["states"])
    if count < n:
        have = _draw(task, path, have, count, n)
    assert have is not None
    return {**have, **{k: have[k][:n] for k in SAMPLED_PER_SEED}}


def _draw(
    task: str, path: Path, have: dict[str, np.ndarray] | None, count: int, n: int
) -> dict[str, np.ndarray]:
    """`have` extended with the draws of seeds ``count..n-1``, written after each block."""
    blocks = [(a, min(n, a + SAMPLED_BLOCK)) for a in range(count, n, SAMPLED_BLOCK)]
    n_workers = min(len(blocks), os.cpu_count() or 1)
    _say(
        f"drawing {task}'s initial states {count}..{n - 1} by LIBERO's reset, once "
        f"({n_workers} workers)"
    )
    todo = list(reversed(blocks))
    done: dict[int, dict[str, Any]] = {}
    lock = threading.Lock()
    start = time.perf_counter()

    def work() -> None:
        log = None
        try:
            with task_worker(task) as (worker, log):
                while True:
                    with lock:
                        if not todo:
                            return
                        a, b = todo.pop()
                    kwargs = {"start": a, "stop": b}
                    msg = {"op": "call", "method": "sampled_states", "kwargs": kwargs}
                    new = worker.call(msg, TIMEOUT_S)
                    with lock:
                        done[a] = new
        except (RemoteError, WorkerFailure) as e:
            with lock:
                todo.clear()  # the other workers stop after their block
            raise ConfigError(
                f"drawing LIBERO task {task!r}'s initial states failed: {e} (log: {log})"
            ) from None

    with concurrent.futures.ThreadPoolExecutor(n_workers) as pool:
        futures = [pool.submit(work) for _ in range(n_workers)]
        try:
            while count < n:
                with lock:
                    ready = done.pop(count, None)
                if ready is None:
                    if all(f.done() for f in futures):
                        break  # a worker failed: its error is raised below
                    time.sleep(0.2)
                    continue
                have = _grown(have, ready)
                _write_npz(path, have)  # the prefix drawn so far: an interrupt keeps it
                count = len(have["states"])
                _say(f"  {count}/{n} drawn ({time.perf_counter() - start:.0f} s)")
        finally:
            with lock:
                todo.clear()  # an interrupt: the workers stop after their block
        for f in futures:
            f.result()
    assert have is not None
    return have


def _grown(have: dict[str, np.ndarray] | None, new: dict[str, Any]) -> dict[str, np.ndarray]:
    """`have` with the seeds of `new` (the next block) appended."""
    new = {k: np.asarray(v) for k, v in new.items()}
    if have is None:
        return {"format": np.asarray(FORMAT), "sampled_format": np.asarray(SAMPLED_FORMAT), **new}
    if not np.array_equal(have["fixture_ids"], new["fixture_ids"]):
        raise ConfigError("LIBERO's fixtures changed between blocks of drawn initial states")
    grown = {k: np.concatenate([have[k], new[k]]) for k in SAMPLED_PER_SEED}
    return {**have, **grown}


def _write_npz(path: Path, arrays: dict[str, np.ndarray]) -> None:
    with atomic_path(path) as tmp, tmp.open("wb") as f:  # a file: savez names no suffix
        np.savez(f, **arrays)


def bundled(path: str) -> str:
    """`path` (a file in the worker environment's packages) as kept in the export cache's
    ``files/`` folder, copied there on first use: a cache carried to another machine (a GPU
    host without the worker environment) holds every file the physics model reads."""
    parts = Path(os.path.normpath(path)).parts
    rel = parts[parts.index("site-packages") + 1 :] if "site-packages" in parts else parts[-1:]
    kept = models_root() / "files" / Path(*rel)
    if not kept.exists():
        if not Path(path).exists():
            raise ConfigError(f"LIBERO asset {path!r} is missing and not in {kept.parent}")
        kept.parent.mkdir(parents=True, exist_ok=True)
        tmp = kept.with_name(f".{kept.name}.{os.getpid()}")
        shutil.copyfile(path, tmp)
        os.replace(tmp, kept)
    return str(kept)


def _drop_visuals(spec: mujoco.MjSpec) -> None:
    """Delete the geoms that collide with nothing and the assets only they use."""
    for geom in list(spec.geoms):
        if geom.contype == 0 and geom.conaffinity == 0:
            spec.delete(geom)
    used = {g.meshname for g in spec.geoms if g.meshname}
    for mesh in list(spec.meshes):
        if mesh.name not in used:
            spec.delete(mesh)
    used_materials = {g.material for g in spec.geoms if g.material}
    for material in list(spec.materials):
        if material.name not in used_materials:
            spec.delete(material)
    used_textures = {t for mat in spec.materials for t in mat.textures if t}
    for texture in list(spec.textures):
        if texture.name not in used_textures:
            spec.delete(texture)


def physics_spec(model: TaskModel, visuals: bool = False) -> mujoco.MjSpec:
    """The mirror's model of the task: collision geoms only, exported inertials pinned.

    `visuals`: keep LIBERO's visual geoms (none collides) with their meshes, materials and
    textures, for cameras; their files are bundled like the collision meshes' (about 80 MB
    for a task). The inertials are pinned either way, so the physics is the same (tested)."""
    spec = mujoco.MjSpec.from_string(model.xml)
    a = model.arrays
    if not visuals:
        _drop_visuals(spec)
    else:  # every geom and site kept, in the compiled model's order: LIBERO's colours
        for kind in ("geom", "site"):
            elements, rgba = getattr(spec, f"{kind}s"), a[f"{kind}_rgba"]
            if len(elements) != len(rgba):
                raise ConfigError(f"LIBERO task {model.task}: {kind}s differ from its export")
            for element, colour in zip(elements, rgba, strict=True):
                element.rgba = colour
    for asset in [*spec.meshes, *spec.textures]:
        if asset.file:
            asset.file = bundled(asset.file)
    names = [str(n) for n in model.meta["body_names"]]
    for i, name in enumerate(names[1:], start=1):  # the world body has no inertial
        body = spec.body(name)
        if body is None:
            raise ConfigError(f"LIBERO task {model.task}: body {name!r} missing from its MJCF")
        body.explicitinertial = True
        body.mass = float(a["body_mass"][i])
        body.inertia = a["body_inertia"][i]
        body.ipos = a["body_ipos"][i]
        body.iquat = a["body_iquat"][i]
        body.pos = a["body_pos"][i]  # where LIBERO's reset puts the fixtures
        body.quat = a["body_quat"][i]
    return spec
