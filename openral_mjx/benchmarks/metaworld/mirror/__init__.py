"""`metaworld_mjx`: MetaWorld v3 tasks mirrored natively on `mjx`, `warp` and `c` (see `scene`)."""

from openral_mjx.benchmarks.metaworld.host_scene import suite_tasks
from openral_mjx.benchmarks.metaworld.mirror.assets import ENV
from openral_mjx.benchmarks.metaworld.mirror.options import MetaWorldMjxOptions
from openral_mjx.benchmarks.metaworld.mirror.scene import MetaWorldMjx
from openral_mjx.scenes import SceneEntry

# `SCENES`'s entry for `metaworld_mjx`; the mirror compiles MetaWorld's own model files, which
# come from the `metaworld` worker environment
SCENE = SceneEntry(
    MetaWorldMjxOptions,
    MetaWorldMjx,
    "sawyer",
    suites=suite_tasks,
    worker_env=ENV,
    expert="metaworld-expert",
)

__all__ = ["SCENE", "MetaWorldMjx", "MetaWorldMjxOptions"]
