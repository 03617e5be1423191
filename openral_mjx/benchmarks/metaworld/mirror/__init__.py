"""`metaworld_mjx`: MetaWorld v3 tasks mirrored natively on `mjx`, `warp` and `c` (see `scene`)."""

from openral_mjx.benchmarks.metaworld import host_scene
from openral_mjx.benchmarks.metaworld.mirror.assets import ENV
from openral_mjx.benchmarks.metaworld.mirror.options import MetaWorldMjxOptions
from openral_mjx.benchmarks.metaworld.mirror.scene import MetaWorldMjx
from openral_mjx.scenes import SceneEntry

# `SCENES`'s entry for `metaworld_mjx`, with the host scene's robot, tasks and suites; the mirror
# compiles MetaWorld's own model files, which come from the `metaworld` worker environment
SCENE = SceneEntry(
    MetaWorldMjxOptions,
    MetaWorldMjx,
    host_scene.ROBOT,
    suites=host_scene.suite_tasks,
    worker_env=ENV,
    tasks=host_scene.SCENE.tasks,
    suite_names=host_scene.SCENE.suite_names,
    expert="metaworld-expert",
    mirrors="metaworld",
)

__all__ = ["SCENE", "MetaWorldMjx", "MetaWorldMjxOptions"]
