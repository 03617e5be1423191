"""How a process waits for its GPU: by giving its CPU core back (CUDA's blocking sync) rather
than spinning on it, for processes that share one machine's cores (a suite's task processes).

CUDA's default (`CU_CTX_SCHED_AUTO`) spins a core while a process waits for its GPU whenever
the process has fewer contexts than the machine has cores, as every task process has. Sixteen
of them on sixteen cores then spin cores that the others' scene builds, traces and compiles
need: the four LIBERO suites in one pool of 16 task processes took 291.3 s warm, and 278.1 s
with blocking sync, side by side on one H200 whose cores were busy throughout (BENCHMARKS.md).
A wait then costs a wake-up (microseconds), against a control step of tens of milliseconds.

The setting is the primary context's, which JAX, torch and Warp all use, so it must come before
any of them starts CUDA in the process. It goes through the CUDA driver's C API (`ctypes`): no
library this project uses sets it.
"""

from __future__ import annotations

import ctypes

CU_CTX_SCHED_BLOCKING_SYNC = 0x04  # cuda.h: block the waiting CPU thread on a sync primitive


def block_while_waiting(libcuda: str = "libcuda.so.1") -> int:
    """Make every visible GPU's primary context wait by blocking, before anything in this
    process starts CUDA. Returns how many devices took the setting: 0 without a CUDA driver
    (a CPU machine) or where it refused (a context already started, on older drivers)."""
    try:
        cuda = ctypes.CDLL(libcuda)
    except OSError:
        return 0
    count = ctypes.c_int(0)
    if cuda.cuInit(0) != 0 or cuda.cuDeviceGetCount(ctypes.byref(count)) != 0:
        return 0
    set_on = 0
    for ordinal in range(count.value):
        device = ctypes.c_int(0)
        if cuda.cuDeviceGet(ctypes.byref(device), ordinal) != 0:
            continue
        if cuda.cuDevicePrimaryCtxSetFlags(device, CU_CTX_SCHED_BLOCKING_SYNC) == 0:
            set_on += 1
    return set_on
