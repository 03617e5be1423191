"""Camera observations that a backend renders rather than ray casts, and sensor keys."""

from __future__ import annotations

import dataclasses

from openral_mjx.core.options import check
from openral_mjx.raycast import VISIBLE_GROUPS, DepthSpec, LaserSpec


@dataclasses.dataclass(frozen=True)
class RgbStyle:
    """How RGB images are drawn (one style per render context: every RGB image of a scene).

    Attributes:
        textures: the materials' textures and the model's skybox behind everything (as
            MuJoCo's renderer draws them); off, surfaces take their material's colour and
            the background is black.
        shadows: lights that cast shadows (`castshadow`) add nothing where they are blocked,
            as in MuJoCo's renderer. Costs a ray per such light and pixel.
        samples: sub-pixel samples per axis, averaged (anti-aliasing, as MuJoCo's multisampled
            offscreen buffer smooths edges); costs `samples`**2 renders.
        texels: on `warp`, each texture wider than `texels` is drawn from its mipmap level
            that wide, standing in for the mipmaps MuJoCo's renderer samples a minified
            texture from (MuJoCo-Warp samples the one level it is given: at full size fine
            patterns alias into noise); 0 draws the textures as they are. Costs nothing per
            frame, and the smaller textures take less device memory.
    """

    textures: bool = False
    shadows: bool = False
    samples: int = 1
    texels: int = 0

    def __post_init__(self) -> None:
        check(self.samples >= 1, f"rgb samples={self.samples}: must be >= 1")
        check(self.texels >= 0, f"rgb texels={self.texels}: must be >= 0 (0: no prefilter)")


@dataclasses.dataclass(frozen=True)
class RgbSpec:
    """An RGB image of MJCF camera `camera`, width x height pixels, values in [0, 1].

    `warp` renders them with MuJoCo-Warp's batch renderer, `c` with MuJoCo's OpenGL renderer
    (`c_render`); on `mjx` asking for one is a `ConfigError`. Intrinsics are the camera's own,
    scaled to the image.
    """

    camera: str
    width: int
    height: int
    name: str | None = None
    groups: tuple[int, ...] = VISIBLE_GROUPS
    style: RgbStyle = RgbStyle()

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
