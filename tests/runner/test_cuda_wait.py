"""Task processes wait for their GPU by blocking, not spinning a core: the CUDA driver calls
that set it, against a stand-in driver that records them, and no effect without a driver."""

import ctypes

import pytest

from openral_mjx.evaluation import suite as suite_module
from openral_mjx.runner import cuda_wait


class _Driver:
    """The CUDA driver functions `block_while_waiting` calls: `devices` GPUs, `init` the
    result of cuInit, `refuse` the ordinals whose primary context refuses new flags."""

    def __init__(self, devices: int, init: int = 0, refuse: tuple[int, ...] = ()):
        self.devices, self.init, self.refuse = devices, init, refuse
        self.flags: dict[int, int] = {}

    def cuInit(self, flags):
        return self.init

    def cuDeviceGetCount(self, count):
        count._obj.value = self.devices
        return 0

    def cuDeviceGet(self, device, ordinal):
        device._obj.value = 100 + ordinal  # a handle, not the ordinal
        return 0

    def cuDevicePrimaryCtxSetFlags(self, device, flags):
        if device.value - 100 in self.refuse:
            return 708  # CUDA_ERROR_PRIMARY_CONTEXT_ACTIVE
        self.flags[device.value] = flags
        return 0


def _with_driver(monkeypatch, driver: _Driver) -> None:
    monkeypatch.setattr(cuda_wait.ctypes, "CDLL", lambda name: driver)


def test_every_gpus_primary_context_is_set_to_block(monkeypatch):
    driver = _Driver(devices=2)
    _with_driver(monkeypatch, driver)
    assert cuda_wait.block_while_waiting() == 2
    assert driver.flags == {100: 4, 101: 4}  # CU_CTX_SCHED_BLOCKING_SYNC on each


def test_a_refusing_or_missing_driver_sets_nothing():
    """A device whose context refuses, a driver that does not start, or none at all (this
    CPU machine: ctypes finds no libcuda) count as not set, and nothing raises."""
    with pytest.MonkeyPatch.context() as patch:
        driver = _Driver(devices=2, refuse=(0,))
        _with_driver(patch, driver)
        assert cuda_wait.block_while_waiting() == 1 and driver.flags == {101: 4}
        driver = _Driver(devices=1, init=100)  # CUDA_ERROR_NO_DEVICE
        _with_driver(patch, driver)
        assert cuda_wait.block_while_waiting() == 0 and driver.flags == {}
    with pytest.raises(OSError):
        ctypes.CDLL("libopenral_mjx_no_such_driver.so")
    assert cuda_wait.block_while_waiting("libopenral_mjx_no_such_driver.so") == 0


def test_task_processes_sharing_a_machine_block_and_a_lone_one_spins(monkeypatch):
    calls: list[int] = []
    monkeypatch.setattr(suite_module, "block_while_waiting", lambda: calls.append(1) or 1)
    monkeypatch.setenv("XLA_PYTHON_CLIENT_PREALLOCATE", "false")  # restored after the test
    try:
        suite_module._start_task_process(None, 1)
        assert calls == []
        suite_module._start_task_process(None, 4)
        assert calls == [1]
    finally:
        suite_module.share_devices(1)
