"""Where a batch of envs runs: every device runs the same single-device program on its slice.

The batch is a global `jax.Array` sharded over a 1-D mesh of devices along the env axis
(`jax.sharding`), and each device's slice goes through one single-device executable, launched
from one thread per device, so the devices run side by side. There is no
partitioner in the way: no envs ever talk to each other, so nothing needs one, and XLA's
Shardy partitioner crashed (segfault, 2 x H200, JAX 0.11) compiling an MJX episode under
`shard_map`. Outputs come back as global arrays of the same mesh, so several processes (each
with its own local devices, after `jax.distributed.initialize`) work the same way.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import jax
import numpy as np
from jax.experimental import multihost_utils
from jax.sharding import Mesh, NamedSharding
from jax.sharding import PartitionSpec as P

Lower = Callable[[Callable, tuple], Any]  # (jitted fn, args on one device) -> jax Lowered


def _plain_lower(fn: Callable, args: tuple) -> Any:
    return fn.lower(*args)


# XLA options for the runner's programs on GPUs. XLA's GPU autotuner times kernel variants on
# scratch buffers as large as the program's own, while compiling: a batch too large for the
# GPU then fails to compile ("Failed to get configs") instead of being measured and shrunk to
# fit, and what it took stays in the process's allocator pool, out of reach of the other
# processes sharing the GPU (a suite's task processes ran out of memory so, MT50 on `mjx`).
# Without it XLA picks its kernels by its own heuristics. Measured: BENCHMARKS.md, issue 38.
GPU_COMPILER_OPTIONS = {"xla_gpu_autotune_level": 0}


def compiler_options(device: jax.Device) -> dict[str, Any]:
    """The XLA options the runner compiles its programs with on `device`."""
    return dict(GPU_COMPILER_OPTIONS) if device.platform == "gpu" else {}


def _persistent_cache_on() -> bool:
    return bool(jax.config.jax_enable_compilation_cache and jax.config.jax_compilation_cache_dir)


@dataclasses.dataclass(frozen=True)
class Layout:
    """A 1-D mesh of devices over the env axis."""

    devices: tuple[jax.Device, ...]

    @property
    def mesh(self) -> Mesh:
        return Mesh(np.array(self.devices), ("env",))

    @property
    def local_devices(self) -> tuple[jax.Device, ...]:
        """The devices of this process (all of them on one host)."""
        return tuple(d for d in self.devices if d.process_index == jax.process_index())

    def put_replicated(self, tree: Any) -> Any:
        return jax.device_put(tree, NamedSharding(self.mesh, P()))

    def put_envs(self, x: np.ndarray) -> jax.Array:
        """Shard a host array over devices along its first axis (each process its slices)."""
        sharding = NamedSharding(self.mesh, P("env"))
        return jax.make_array_from_callback(x.shape, sharding, lambda index: x[index])

    def get(self, tree: Any) -> Any:
        if jax.process_count() > 1:
            return multihost_utils.process_allgather(tree, tiled=True)
        return jax.device_get(tree)

    def local(self, tree: Any, device: jax.Device) -> Any:
        """Each array of `tree` (put by `put_envs` or `put_replicated`) as its slice on
        `device`."""

        def slice_on(x: jax.Array) -> jax.Array:
            for shard in x.addressable_shards:
                if shard.device == device:
                    return shard.data
            raise ValueError(f"no slice of an array of shape {x.shape} on {device}")

        return jax.tree.map(slice_on, tree)

    def local_args(self, args: Any) -> dict[jax.Device, Any]:
        """`local(args, d)` for every local device, taken in the calling thread before `launch`
        starts the device threads: the threads then only run programs, and never read the
        arrays' shard lists concurrently."""
        return {d: self.local(args, d) for d in self.local_devices}

    def assemble(self, parts: list[Any], out_axes: Any) -> Any:
        """The global arrays of per-device outputs (one tree per local device): leaves under an
        entry `k` of `out_axes` (a prefix of the outputs' tree) concatenate along axis `k`."""

        def whole(axis: int, *trees: Any) -> Any:
            sharding = NamedSharding(self.mesh, P(*([None] * axis), "env"))

            def one(*xs: jax.Array) -> jax.Array:
                shape = list(xs[0].shape)
                shape[axis] *= len(self.devices)
                return jax.make_array_from_single_device_arrays(tuple(shape), sharding, list(xs))

            return jax.tree.map(one, *trees)

        return jax.tree.map(whole, out_axes, *parts)

    def launch(self, run: Callable[[jax.Device], Any]) -> list[Any]:
        """`run(device)` for every local device, each from its own thread: a GPU program with
        loops keeps its launching thread busy until most of its kernels are queued, so one
        thread would run the devices one after another."""
        devices = self.local_devices
        if len(devices) == 1:
            return [run(devices[0])]
        with ThreadPoolExecutor(len(devices)) as pool:
            return list(pool.map(run, devices))

    def per_device(self, fn: Callable, out_axes: Any = 0) -> PerDevice:
        """`fn` (of a batch of envs, and replicated arguments) on every device's slice."""
        return PerDevice(jax.jit(fn), self, out_axes)


@dataclasses.dataclass(frozen=True)
class PerDevice:
    """A jitted single-device function run on each device's slice of its arguments (see
    `Layout`). Called directly, it compiles on first use per device; `compile` builds the
    executables ahead of time (through a caller's `lower`, e.g. an export cache)."""

    fn: Callable
    layout: Layout
    out_axes: Any = 0

    def __call__(self, *args: Any) -> Any:
        local = self.layout.local_args(args)
        parts = self.layout.launch(lambda d: self.fn(*local[d]))
        return self.layout.assemble(parts, self.out_axes)

    def compile(self, args: tuple, lower: Lower = _plain_lower) -> Program:
        """One executable per local device, for arguments shaped like `args` (global arrays),
        compiled in parallel threads. On GPUs with JAX's persistent compilation cache on (the
        default here), whose keys ignore which GPU, the first compiles alone and the rest load
        what it wrote. On GPUs without XLA's autotuner (`compiler_options`)."""
        devices = self.layout.local_devices
        lowered = [lower(self.fn, self.layout.local(args, d)) for d in devices]
        options = compiler_options(devices[0])
        first: list[Any] = []
        if devices[0].platform == "gpu" and _persistent_cache_on():
            first, lowered = [lowered[0].compile(compiler_options=options)], lowered[1:]
        with ThreadPoolExecutor(max(1, len(lowered))) as pool:
            rest = list(pool.map(lambda low: low.compile(compiler_options=options), lowered))
        return Program(self.layout, (*first, *rest), self.out_axes)


@dataclasses.dataclass(frozen=True)
class Program:
    """Compiled `PerDevice`: one executable per local device."""

    layout: Layout
    executables: tuple[Any, ...]
    out_axes: Any

    def __call__(self, *args: Any) -> Any:
        executables = dict(zip(self.layout.local_devices, self.executables, strict=True))
        local = self.layout.local_args(args)
        parts = self.layout.launch(lambda d: executables[d](*local[d]))
        return self.layout.assemble(parts, self.out_axes)

    def memory_analysis(self) -> Any:
        """XLA's memory estimate of one device's executable (all are the same program)."""
        return self.executables[0].memory_analysis()
