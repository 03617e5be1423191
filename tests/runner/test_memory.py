"""Fitting a batch into device memory, alone and as one of several processes on a device."""

from __future__ import annotations

import jax
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


class _GpuDevice:
    platform = "gpu"


class _Lowered:
    def __init__(self) -> None:
        self.options: list[dict] = []

    def compile(self, compiler_options=None):
        self.options.append(compiler_options)
        return object()


@pytest.mark.parametrize("cache_on", [True, False])
def test_gpu_programs_compile_without_xla_s_autotuner(cache_on, monkeypatch):
    """On a GPU every executable the runner builds is compiled with autotuning off (its
    scratch buffers are as large as the program's: a too-large batch would fail to compile
    instead of shrinking); on a CPU with no options."""
    from openral_mjx.runner import device_layout

    assert device_layout.compiler_options(_GpuDevice()) == {"xla_gpu_autotune_level": 0}
    assert device_layout.compiler_options(jax.devices("cpu")[0]) == {}
    monkeypatch.setattr(device_layout, "_persistent_cache_on", lambda: cache_on)
    layout = device_layout.Layout((_GpuDevice(), _GpuDevice()))
    monkeypatch.setattr(device_layout.Layout, "local_devices", property(lambda s: s.devices))
    monkeypatch.setattr(device_layout.Layout, "local", lambda s, args, d: args)
    made: list[_Lowered] = []

    def lower(fn, args):
        made.append(_Lowered())
        return made[-1]

    program = device_layout.PerDevice(lambda x: x, layout).compile((1,), lower)
    assert len(program.executables) == 2
    assert [lo.options for lo in made] == [[{"xla_gpu_autotune_level": 0}]] * 2
