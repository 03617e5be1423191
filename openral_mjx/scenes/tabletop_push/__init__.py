"""`tabletop_push`: push a cube to a goal disc on a table, with any position-controlled arm.

The robot (a registered one, or a user MJCF with position servos and an end-effector site, as
published: it starts at its `home` keyframe and its base is placed within its measured reach)
is loaded into an `MjSpec`; table, cube (freejoint), goal disc, floor, light and cameras are
appended. Reset samples the cube pose and a goal at a random bearing and distance from it.

Action: one position target per actuator, clipped to its ctrlrange.

Observation (flat, float32; named slices in `obs_layout`): robot joint positions and velocities,
end-effector position, cube position and quaternion (w, x, y, z), goal position (x, y), all in
the world frame (metres, radians).

Reward (dense, per control step): ``-|cube_xy - goal_xy| - 0.5 |ee - cube| + 1[success]``:
bring the tool to the cube, the cube to the goal.

Success: the cube centre within `goal_radius` of the goal (in the table plane) while the cube
rests on the table: centre height within `rest_height_tol` of half an edge above the top face,
and speed below `rest_speed`. The episode ends on success (or divergence, or at max steps).

Episode factors (for the report's breakdown), from the reset state: `goal_distance` (cube centre
to goal in the table plane, m), `cube_x`, `cube_y` (initial cube position, m), and
`push_face_angle` (rad, in [0, pi/4]): the angle between the cube->goal direction and the
nearest cube face normal; 0 is a push square onto a face, pi/4 onto an edge.

Parts: `options` (the typed options, robot choice), `arm` (what is measured on the robot when
the scene is built: start pose, servos held still, integrator, tool size, reach, base
placement), `model` (MjSpec composition: `compose`), `task` (reset sampling, success predicate,
reward, episode factors as pure JAX), `observation` (layout and assembly), `scene` (the
`TabletopPush` scene wiring them to a physics backend).
"""

from openral_mjx.scenes.tabletop_push.model import compose
from openral_mjx.scenes.tabletop_push.options import TabletopPushOptions
from openral_mjx.scenes.tabletop_push.scene import TabletopPush

__all__ = ["TabletopPush", "TabletopPushOptions", "compose"]
