"""Robot descriptions (MJCF written in this project) and the `ROBOTS` registry."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from openral_mjx.core.registry import Registry

_HERE = Path(__file__).parent


@dataclasses.dataclass(frozen=True)
class RobotSpec:
    """What a scene needs to know about a robot: its MJCF, end-effector site and home pose.

    `home_qpos` maps joint names to initial positions (rad or m); joints not named start at 0.
    The end-effector site's +z axis is taken to point out of the tool (used by scripted experts).
    """

    name: str
    mjcf_path: Path
    ee_site: str
    home_qpos: dict[str, float] = dataclasses.field(default_factory=dict)


ROBOTS: Registry[RobotSpec] = Registry("robot")

ROBOTS.register("so101")(
    RobotSpec(
        name="so101",
        mjcf_path=_HERE / "so101.xml",
        ee_site="ee",
        # Folded above the table, tool pointing down and forward.
        home_qpos={"shoulder_lift": -1.2, "elbow_flex": 1.2, "wrist_flex": 1.2},
    )
)


def user_robot(mjcf_path: Path, ee_site: str) -> RobotSpec:
    """A robot given by the user as an MJCF file (`--robot-mjcf`)."""
    return RobotSpec(name=f"mjcf:{mjcf_path.name}", mjcf_path=mjcf_path, ee_site=ee_site)


__all__ = ["ROBOTS", "RobotSpec", "user_robot"]
