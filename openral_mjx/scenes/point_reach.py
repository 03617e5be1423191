"""`point_reach`: a toy gym-style simulator run through the host adapter in this environment.

The smallest host scene: `openral_mjx.host.point_reach.PointReachEnv` (a point moving towards
one of 8 targets) in worker processes of the evaluator's own interpreter. It exercises the
whole host path (workers, callbacks, faults) without a separate environment, and is the
template for wrapping another gym-style simulator: a factory path, its observation and action
layout, and a `HostSceneSpec`.
"""

from __future__ import annotations

import dataclasses

from openral_mjx.core.options import check
from openral_mjx.host.envs import ensure_env
from openral_mjx.host.point_reach import FAULTS, IMAGE, TARGETS
from openral_mjx.scenes.host_scene import HostOptions, HostScene, HostSceneSpec


@dataclasses.dataclass(frozen=True)
class PointReachOptions(HostOptions):
    """`point_reach` options; `fault*` inject a worker fault (see `PointReachEnv`)."""

    max_steps: int = 40
    fault: str | None = None
    fault_init_state: int = -1
    fault_step: int = 0

    def __post_init__(self) -> None:
        super().__post_init__()
        check(self.max_steps >= 1, f"option max_steps={self.max_steps}: must be >= 1")
        check(
            self.fault is None or self.fault in FAULTS,
            f"option fault={self.fault!r}; valid: {', '.join(FAULTS)}",
        )


def point_reach(options: PointReachOptions, **_: object) -> HostScene:
    o = options
    batch = o.batch_config(
        "openral_mjx.host.point_reach:make",
        {"fault": o.fault, "fault_init_state": o.fault_init_state, "fault_step": o.fault_step},
        {"state": ((4,), "float32"), "image": ((IMAGE, IMAGE, 3), "uint8")},
        action_size=2,
    )
    spec = HostSceneSpec(
        name="point_reach",
        task="reach_target",
        robot="point",
        batch=batch,
        action_low=(-1.0, -1.0),
        action_high=(1.0, 1.0),
        control_dt=0.05,
        max_steps=o.max_steps,
        n_init_states=len(TARGETS),
        instruction="move the point to the target",
    )
    return HostScene(spec, o, "core", ensure_env("core"))
