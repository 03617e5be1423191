"""Fitting a batch into device memory: XLA's estimate of a compiled episode's footprint
against what the device's allocator can still hand out."""

from __future__ import annotations

from typing import Any

import jax


def peak_bytes(compiled: Any) -> int | None:
    """XLA's estimate of a compiled function's device memory (arguments, outputs, scratch)."""
    try:
        m = compiled.memory_analysis()
    except Exception:  # not every backend implements it
        return None
    if m is None:
        return None
    return int(m.temp_size_in_bytes + m.argument_size_in_bytes + m.output_size_in_bytes)


_SHARERS = [1]  # processes running at once on this process's devices (see share_devices)


def share_devices(processes: int) -> None:
    """This process is one of `processes` started together on the same devices (a suite's
    task processes): size its batches for its share of each device's memory. Each process's
    allocator sees only its own use, so without this every one plans for the whole device
    and together they run out of it."""
    if processes < 1:
        raise ValueError(f"processes must be at least 1, got {processes}")
    _SHARERS[0] = processes


def free_device_bytes(device: jax.Device) -> int | None:
    """Bytes the device's allocator can still hand out to this process, within its share of
    the device (see `share_devices`); None on backends that do not say."""
    stats = device.memory_stats() or {}
    if "bytes_limit" not in stats:
        return None
    return int(stats["bytes_limit"] // _SHARERS[0] - stats.get("bytes_in_use", 0))


def fit_batch(per_device: int, need: int | None, free: int | None, fraction: float) -> int:
    """The per-device batch that fits `fraction` of `free` bytes, given that `per_device` envs
    need `need` bytes (memory grows ~linearly with envs); a multiple of 64 when that large."""
    if need is None or free is None or need <= fraction * free:
        return per_device
    target = int(per_device * fraction * free / need)
    return max(1, target // 64 * 64 if target >= 64 else target)
