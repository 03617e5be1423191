"""`libero_mjx`: LIBERO's tasks mirrored natively on our backends (see `scene`)."""

from openral_mjx.benchmarks.libero import host_scene
from openral_mjx.benchmarks.libero.assets import ENV
from openral_mjx.benchmarks.libero.mirror.options import LiberoMjxOptions
from openral_mjx.benchmarks.libero.mirror.scene import LiberoMjx
from openral_mjx.scenes import SceneEntry

# `warp` contacts per env (MuJoCo-Warp counts its broadphase pairs against the same buffer):
# LIBERO's scenes hold 18-87 contacts after their settle steps, and libero-expert's episodes
# of libero_spatial/0 and libero_object/0 at most 93 contacts and 62 pairs (measured); 256
# ran 4,096 envs of libero_spatial/0 on an H200 with none overflowing. An env that overflows
# is counted diverged, never silently wrong.
CONTACTS_PER_ENV = 256

# `SCENES`'s entry for `libero_mjx`, with the host scene's robot, tasks and suites. Its model
# and facts come from LIBERO in the `lerobot-libero` worker environment (`assets`).
SCENE = SceneEntry(
    LiberoMjxOptions,
    LiberoMjx,
    host_scene.ROBOT,
    backends=("c", "warp"),  # mjx: builds, but its step did not compile in 15 min on a CPU
    suites=host_scene.suite_tasks,
    worker_env=ENV,
    tasks=host_scene.SCENE.tasks,
    suite_names=host_scene.SCENE.suite_names,
    expert="libero-expert",
    mirrors="libero",
    seed_options=host_scene.SCENE.seed_options,
    seed_cycles=host_scene.SCENE.seed_cycles,
    contacts_per_env=CONTACTS_PER_ENV,
    task_steps=host_scene.task_steps,
)

__all__ = ["SCENE", "LiberoMjx", "LiberoMjxOptions"]
