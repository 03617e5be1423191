"""Robot descriptions (MJCF written in this project) and the `ROBOTS` registry."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from openral_mjx.core.registry import Registry

_HERE = Path(__file__).parent


@dataclasses.dataclass(frozen=True)
class RobotSpec:
    """What a scene needs to know about a robot: its MJCF, end-effector site and home pose.

    `home_qpos` maps joint names to initial positions (rad or m) over qpos0; empty: the MJCF's
    `home` keyframe if it has one, else qpos0. The end-effector site's +z axis is taken to point
    out of the tool (used by scripted experts). `tool_radius` (m): how far the tool reaches
    sideways from the site, for pushing; None: measured from the end-effector's collision geoms.
    """

    name: str
    mjcf_path: Path
    ee_site: str
    home_qpos: dict[str, float] = dataclasses.field(default_factory=dict)
    tool_radius: float | None = None


ROBOTS: Registry[RobotSpec] = Registry("robot")

ROBOTS.register("so101")(
    RobotSpec(
        name="so101",
        mjcf_path=_HERE / "so101.xml",
        ee_site="ee",
        # Folded above the table, tool pointing down and forward.
        home_qpos={"shoulder_lift": -1.2, "elbow_flex": 1.2, "wrist_flex": 1.2},
        # The fixed finger's contact face, 1 cm from the site; its geoms measure 2.1 cm at
        # their farthest corner, which would keep the expert a centimetre short of the cube.
        tool_radius=0.01,
    )
)


def user_robot(mjcf_path: Path, ee_site: str) -> RobotSpec:
    """A robot given by the user as an MJCF file (`--robot-mjcf`)."""
    return RobotSpec(name=f"mjcf:{mjcf_path.name}", mjcf_path=mjcf_path, ee_site=ee_site)


__all__ = ["ROBOTS", "RobotSpec", "user_robot"]
