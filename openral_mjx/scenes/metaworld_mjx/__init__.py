"""`metaworld_mjx`: MetaWorld v3 tasks mirrored natively on `mjx`, `warp` and `c` (see `scene`)."""

from openral_mjx.scenes.metaworld_mjx.options import MetaWorldMjxOptions
from openral_mjx.scenes.metaworld_mjx.scene import MetaWorldMjx

__all__ = ["MetaWorldMjx", "MetaWorldMjxOptions"]
