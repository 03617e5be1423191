"""`so101_box`: insert a tube into a slotted block's hole with the SO-101, in a box arena.

World frame: origin on the floor at the robot's base, +x forward, +z up. The arena (default
100 cm wide along y, 61.5 cm deep along x, 75 cm high) has a floor, four walls (planes facing
in) and a ceiling light; the SO-101 stands at the middle of the back wall. Cameras: `overhead`
(OAK-D Pro-like, looking straight down from the ceiling: 640 x 400 px, fx = fy = 383 px, cx, cy
at the image centre, i.e. HFOV 80 deg x VFOV 55 deg like its depth stream) and `wrist` (on the
gripper, looking between the finger tips: 640 x 480 px, fx = fy = 320 px); the intrinsics are
options and are written into the MJCF cameras (resolution, focal and principal point in
pixels, sensor pitch 3 um).

Objects. The block (44.5 x 44.5 x 20 mm, free, on the floor) has a 23 mm through hole at its
centre and a 5 mm slot from the hole to its +x face. The tube (21.9 x 90 mm, free) stands on
the floor. Reset draws block and tube (x, y, yaw) independently in their spawn ranges until
their footprint circles are `spawn_gap` apart and clear of the robot (`sample_layout`).

Collision shapes, chosen for what MJX's JAX implementation can collide (it has no
cylinder-box or cylinder-mesh pair, and box-box is its most expensive one):

* block: nine boxes, four walls (the +x one split by the slot) around a square hole and four
  45-degree corner boxes that make the hole an octagon whose inscribed circle is the 23 mm
  hole (a square would let the tube off-axis by 0.78 mm diagonally; the octagon by 0.60 mm),
  plus nine thin capsules (`rim_radius` 0.5 mm) along the hole's top edges. The capsules' inner
  surfaces are tangent to the hole's walls, so the clearance is unchanged; they make the
  tube's rounded end meet the rim as an exact capsule-capsule contact: MJX's capsule-box
  collider picks the box face of least penetration, so a tube pressed onto a bare box edge
  slides along the hole's wall instead of resting on the rim. A thin footprint box is the only
  block geom touching the floor and walls.
* tube: a capsule of the tube's radius and full length (what the block and the robot touch)
  and a cylinder (what the floor and walls touch, so it stands on a flat end). The capsule's
  lower end is a hemisphere, a lead-in the real tube does not have: held 1 mm off the hole's
  axis it rests on the rim with its tip ~8 mm into the hole, short of `insertion_depth`.
* robot: the SO-101's primitives, plus a flat pad on the moving jaw that is parallel to the
  fixed finger when the jaws are one tube diameter apart (the pivoting jaw's own finger meets
  the tube at ~15 degrees and tilts it in the grasp); the pad replaces that finger's collisions.
  The arm does not collide with the block (its nine boxes against the three gripper boxes
  would add 27 box-box pairs to every MJX step); it does collide with the tube and the floor.

Contact model: the tube's contacts use `contact_timeconst` (5 ms); with the block, impedance
`block_solimp` (MuJoCo's default); with the fingers, the stiffer `grip_solimp` (the 2.94 N m jaw
servo squeezes the 30 g tube hard: each finger sinks 1.3 mm into it at the default impedance,
0.24 mm at 0.99). 87 contact slots for MJX, all between
primitives (planes, capsules, boxes, cylinders). Tested fit (tests/scenes/test_so101_box_fit.py):
dropped at rest onto the hole with its axis vertical, the tube falls through with its axis
0.4 mm off centre and stays on the rim at 0.7 mm and 1 mm, on MuJoCo C and on MJX alike
(same resting heights within 0.1 mm): the effective radial clearance is in (0.4, 0.7) mm,
against 0.55 mm specified. Pushed down with 2 N instead of its weight, soft contacts let a
tube up to 0.75 mm off the axis squeeze in; at 1 mm it holds even at 10 N.

Physics: 2 ms steps, 10 per 20 ms control step, Newton solver 6 iterations / 8 line-search,
Euler integration (MJX's implicitfast disagrees with MuJoCo C on the servos' damping).

Action: one position target per actuator (5 arm joints and the jaw), clipped to ctrlrange.

Observation (flat, float32; slices in `obs_layout`): joint positions and velocities, the
end-effector site's position, tube position and quaternion (w, x, y, z), block position and
quaternion, world frame.

Reward (dense, per control step): ``-0.5 |grasp site - tube centre| - |tube's lower end -
(hole axis at insertion depth)| + 1[success]``.

Success: the tube inserted vertically into the hole: its axis within `tilt_tolerance` of
vertical (either end down), its lower end at least `insertion_depth` below the block's top
face and within the hole's radius of the hole's axis (both measured in the block's frame).
The episode ends on success or divergence.

Episode factors (for success breakdowns), from the reset state: `tube_block_distance`,
`tube_reach` and `block_reach` (from the robot base, m) and `block_yaw` (rad).

Parts: `options` (the typed options), `model` (MjSpec composition: `compose`), `task` (reset
layout, success predicate, reward, episode factors as pure JAX), `observation` (layout and
assembly), `scene` (the `So101Box` scene wiring them to a physics backend).
"""

from openral_mjx.scenes.so101_box.model import add_block, add_tube, compose
from openral_mjx.scenes.so101_box.options import So101BoxOptions
from openral_mjx.scenes.so101_box.scene import So101Box

__all__ = ["So101Box", "So101BoxOptions", "add_block", "add_tube", "compose"]
