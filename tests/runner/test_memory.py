"""Fitting a batch into device memory, alone and as one of several processes on a device."""

from __future__ import annotations

import pytest

from openral_mjx.evaluation import suite as suite_module
from openral_mjx.runner import memory


class _Gpu:
    """A device whose allocator reports `limit` bytes and `in_use` of them taken."""

    def __init__(self, limit: int, in_use: int) -> None:
        self.stats = {"bytes_limit": limit, "bytes_in_use": in_use}

    def memory_stats(self) -> dict[str, int]:
        return self.stats


@pytest.fixture
def alone():
    yield
    memory.share_devices(1)


def test_a_batch_shrinks_to_what_fits_and_stays_whole_otherwise():
    assert memory.fit_batch(1000, need=40 * 2**30, free=10 * 2**30, fraction=0.85) == 192
    assert memory.fit_batch(1000, need=2**30, free=10 * 2**30, fraction=0.85) == 1000
    assert memory.fit_batch(1000, need=None, free=10 * 2**30, fraction=0.85) == 1000
    assert memory.fit_batch(8, need=100, free=10, fraction=1.0) == 1


def test_task_processes_plan_for_their_share_of_the_device(alone, monkeypatch):
    """MT50 on `mjx` in 16 task processes ran out of GPU memory: each process's allocator saw
    only its own use, so every one sized its batch for the whole card. A task process now
    plans for 1/k of it; the batch it fits shrinks with k."""
    gpu = _Gpu(limit=80 * 2**30, in_use=2**30)
    assert memory.free_device_bytes(gpu) == 79 * 2**30
    monkeypatch.setenv("XLA_PYTHON_CLIENT_PREALLOCATE", "false")  # restored after the test
    suite_module._start_task_process(None, 16)
    assert memory.free_device_bytes(gpu) == 4 * 2**30
    need = 40 * 2**30  # XLA's estimate for 1,000 envs (MetaWorld's mesh collisions on mjx)
    fitted = memory.fit_batch(1000, need, memory.free_device_bytes(gpu), 0.85)
    assert fitted == 64 and need * fitted / 1000 <= 0.85 * 4 * 2**30
    with pytest.raises(ValueError, match="got 0"):
        memory.share_devices(0)


def test_a_cpu_device_says_nothing_and_the_batch_stays():
    class Cpu:
        def memory_stats(self):
            return None

    assert memory.free_device_bytes(Cpu()) is None
