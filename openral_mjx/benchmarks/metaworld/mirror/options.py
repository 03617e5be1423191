"""`metaworld_mjx` options."""

from __future__ import annotations

import dataclasses

from openral_mjx.core.errors import unknown
from openral_mjx.core.options import check
from openral_mjx.scenes.sensor_obs import SensorObsOptions

MAX_PATH_LENGTH = 500


@dataclasses.dataclass(frozen=True)
class MetaWorldMjxOptions(SensorObsOptions):
    """The MetaWorld task (a name of `TASKS`), whether the goal is observed (MT benchmarks:
    true; ML: false, as MetaWorld's goal-hidden envs), and the episode limit (MetaWorld's 500).

    Pixel observations (off by default; `warp`, or `c` with MuJoCo's renderer):
    `obs_rgb_cameras` names cameras of MetaWorld's model (`corner`, `corner2`, `corner3`,
    `corner4`, `topview`, `behindGripper`,
    `gripperPOV`), each an `rgb_CAMERA` slice of `obs_rgb_size` after the 39 state floats,
    drawn with textures, skybox and shadows as MetaWorld's own renders are (how far they
    agree: docs/metaworld_mjx.md). Depth cameras and lasers are ray cast, which knows
    primitive geoms only, and MetaWorld's models are meshes: they are rejected here.
    """

    task: str = "reach-v3"
    goal_observable: bool = True
    max_steps: int = MAX_PATH_LENGTH
    obs_rgb_textures: bool = True
    obs_rgb_shadows: bool = True

    def __post_init__(self) -> None:
        from openral_mjx.benchmarks.metaworld.mirror.tasks import TASKS

        super().__post_init__()
        if self.task not in TASKS:
            raise unknown("MetaWorld mirror task", self.task, sorted(TASKS))
        check(
            1 <= self.max_steps <= MAX_PATH_LENGTH,
            f"option max_steps={self.max_steps}: must be in 1..{MAX_PATH_LENGTH} "
            "(MetaWorld's limit)",
        )
        check(
            not self.obs_depth_cameras and self.obs_laser_frame is None,
            f"options obs_depth_cameras={list(self.obs_depth_cameras)}, "
            f"obs_laser_frame={self.obs_laser_frame!r}: metaworld_mjx observes RGB cameras only "
            "(obs_rgb_cameras, on warp); ray-cast depth and lasers see no meshes",
        )
