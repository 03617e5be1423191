"""Camera observations that a backend renders rather than ray casts, and sensor keys."""

from __future__ import annotations

import dataclasses

from openral_mjx.core.options import check
from openral_mjx.raycast import VISIBLE_GROUPS, DepthSpec, LaserSpec


@dataclasses.dataclass(frozen=True)
class RgbSpec:
    """An RGB image of MJCF camera `camera`, width x height pixels, values in [0, 1].

    Only the `warp` backend renders images (MuJoCo-Warp's batch renderer); elsewhere asking
    for one is a `ConfigError`. Intrinsics are the camera's own, scaled to the image.
    """

    camera: str
    width: int
    height: int
    name: str | None = None
    groups: tuple[int, ...] = VISIBLE_GROUPS

    def __post_init__(self) -> None:
        check(
            min(self.width, self.height) >= 1,
            f"rgb camera {self.key!r}: size {self.width}x{self.height} must be >= 1",
        )

    @property
    def key(self) -> str:
        return self.name or f"rgb_{self.camera}"


SensorSpec = LaserSpec | DepthSpec | RgbSpec


def sensor_key(spec: SensorSpec) -> str:
    """The name a sensor's readings go by."""
    return spec.name if isinstance(spec, LaserSpec) else spec.key
