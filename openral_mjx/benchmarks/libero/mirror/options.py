"""`libero_mjx` options."""

from __future__ import annotations

import dataclasses

from openral_mjx.benchmarks.libero.host_scene import (
    SAMPLED_STATES,
    check_protocol,
    parse_task,
    task_steps,
)
from openral_mjx.core.options import check


@dataclasses.dataclass(frozen=True)
class LiberoMjxOptions:
    """The LIBERO task (``suite/index``, as on the `libero` host scene), the episode limit
    (default: the suite's, as lerobot's LIBERO evaluation sets it), whether the observation
    has the ``expert`` entry that `libero-expert` reads (as on the host scene), and
    `image_size`: None observes no camera (one flat vector: ``state``, ``expert``); a size
    observes the host scene's dict, ``image`` (agentview) and ``wrist_image``
    (robot0_eye_in_hand) square RGB uint8 turned upright as lerobot's LIBERO env turns them,
    beside ``state`` and ``expert`` (backend `c`: MuJoCo's renderer; `warp`: MuJoCo-Warp's).
    `image_samples` (`warp` only): sub-pixel samples per axis, averaged, as MuJoCo's
    multisampled renderer smooths thin lines and edges; 2 draws 4 times per image and brings
    warp's images closer to LIBERO's (docs/libero_mjx.md, "Cameras on warp").
    `protocol` and `sampled_states` choose the initial states as on the host scene:
    ``standard`` (LIBERO's 50 shipped ones) or ``sampled`` (LIBERO's own reset draws, numpy
    seeded with s mod `sampled_states`)."""

    task: str = "libero_spatial/0"
    max_steps: int | None = None
    expert: bool = True
    image_size: int | None = None
    image_samples: int = 1
    protocol: str = "standard"
    sampled_states: int = SAMPLED_STATES

    def __post_init__(self) -> None:
        parse_task(self.task)
        check_protocol(self.protocol, self.sampled_states)
        if self.image_size is not None:
            check(self.image_size >= 8, f"option image_size={self.image_size}: must be >= 8")
        check(
            1 <= self.image_samples <= 4,
            f"option image_samples={self.image_samples}: must be 1 to 4 (samples per axis)",
        )
        check(
            self.image_samples == 1 or self.image_size is not None,
            f"option image_samples={self.image_samples} needs image_size (the cameras)",
        )
        if self.max_steps is not None:
            check(self.max_steps >= 1, f"option max_steps={self.max_steps}: must be >= 1")

    @property
    def episode_limit(self) -> int:
        return self.max_steps or task_steps(self.task)
