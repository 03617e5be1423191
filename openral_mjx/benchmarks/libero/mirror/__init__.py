"""`libero_mjx`: LIBERO's tasks mirrored natively on our backends (see `scene`)."""

from openral_mjx.benchmarks.libero import host_scene
from openral_mjx.benchmarks.libero.mirror.assets import ENV
from openral_mjx.benchmarks.libero.mirror.options import LiberoMjxOptions
from openral_mjx.benchmarks.libero.mirror.scene import LiberoMjx
from openral_mjx.scenes import SceneEntry

# `SCENES`'s entry for `libero_mjx`, with the host scene's robot, tasks and suites. Its model
# and facts come from LIBERO in the `lerobot-libero` worker environment (`assets`). On `c`
# for now: the goal's contact tests read contact sensors, which `mjx` and `warp` lack here.
SCENE = SceneEntry(
    LiberoMjxOptions,
    LiberoMjx,
    host_scene.ROBOT,
    backends=("c",),
    suites=host_scene.suite_tasks,
    worker_env=ENV,
    tasks=host_scene.SCENE.tasks,
    suite_names=host_scene.SCENE.suite_names,
)

__all__ = ["SCENE", "LiberoMjx", "LiberoMjxOptions"]
