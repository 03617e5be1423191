"""`PointReachEnv`: a tiny gym-style simulator, the host adapter's test bed and template.

A point in the unit square moves by ``0.05 * action`` per step (actions clipped to [-1, 1])
towards a target; success when it is within 0.05 of it. The target is one of 8 fixed initial
states (option ``init_state``), given (option ``target``: x, y), or drawn from the reset seed.
Observation: ``state`` = (x, y, target x, target y) float32 and a tiny ``image`` (8 x 8 RGB,
uint8) with the point in red and the target in green, so that image transport is exercised too.

Fault injection, for tests of the adapter's fault handling: the env reset with init state
``fault_init_state`` crashes its worker process (``fault="crash"``), hangs (``"hang"``),
stalls for `STALL_S` and goes on as if nothing happened (``"stall"``: time for a test to kill
its worker), raises (``"raise"``) or reports its physics diverged (``"diverge"``:
``info["diverged"]``) at step ``fault_step``. Runs in any environment with numpy.
"""

from __future__ import annotations

import os
import time
from typing import Any

import numpy as np

TARGETS = np.array(
    [
        [0.8, 0.8],
        [0.2, 0.8],
        [0.8, 0.2],
        [0.2, 0.2],
        [0.5, 0.9],
        [0.9, 0.5],
        [0.5, 0.1],
        [0.1, 0.5],
    ],
    np.float32,
)
STEP = 0.05
RADIUS = 0.05
IMAGE = 8
STALL_S = 3.0
FAULTS = ("crash", "hang", "stall", "raise", "diverge")


class PointReachEnv:
    """See module docstring."""

    def __init__(
        self, fault: str | None = None, fault_init_state: int = -1, fault_step: int = 0
    ) -> None:
        if fault is not None and fault not in FAULTS:
            raise ValueError(f"unknown fault {fault!r}; valid: {', '.join(FAULTS)}")
        self.fault, self.fault_init_state, self.fault_step = fault, fault_init_state, fault_step
        self.pos = np.zeros(2, np.float32)
        self.target = np.zeros(2, np.float32)
        self.t = 0
        self.armed = False

    def _obs(self) -> dict[str, np.ndarray]:
        image = np.zeros((IMAGE, IMAGE, 3), np.uint8)
        for xy, channel in ((self.target, 1), (self.pos, 0)):
            i, j = np.minimum((xy * IMAGE).astype(int), IMAGE - 1)
            image[IMAGE - 1 - j, i, channel] = 255
        return {"state": np.concatenate([self.pos, self.target]), "image": image}

    def _success(self) -> bool:
        return bool(np.hypot(*(self.pos - self.target)) < RADIUS)

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict, dict]:
        options = options or {}
        rng = np.random.default_rng(seed)
        init = options.get("init_state")
        self.target = TARGETS[init] if init is not None else rng.uniform(0.1, 0.9, 2)
        if options.get("target") is not None:
            self.target = np.asarray(options["target"])
        self.target = self.target.astype(np.float32)
        self.pos = rng.uniform(0.3, 0.7, 2).astype(np.float32)
        self.t = 0
        self.armed = self.fault is not None and init == self.fault_init_state
        return self._obs(), {"is_success": self._success()}

    def step(self, action: np.ndarray) -> tuple[dict, float, bool, bool, dict]:
        if self.armed and self.t == self.fault_step and self.fault == "stall":
            time.sleep(STALL_S)
        elif self.armed and self.t == self.fault_step:
            if self.fault == "crash":
                os._exit(3)
            if self.fault == "hang":
                time.sleep(3600)
            if self.fault == "diverge":
                return self._obs(), 0.0, True, False, {"is_success": False, "diverged": True}
            raise RuntimeError(f"injected fault at step {self.t}")
        a = np.clip(np.asarray(action, np.float32), -1.0, 1.0)
        self.pos = np.clip(self.pos + STEP * a, 0.0, 1.0).astype(np.float32)
        self.t += 1
        success = self._success()
        reward = float(-np.hypot(*(self.pos - self.target)))
        return self._obs(), reward, success, False, {"is_success": success}

    def close(self) -> None:
        pass


def make(**kwargs: Any) -> PointReachEnv:
    return PointReachEnv(**kwargs)
