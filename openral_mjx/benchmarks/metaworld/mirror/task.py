"""What a MetaWorld mirror task is: MetaWorld's facts for one task, and its logic in pure JAX.

A `MirrorTask` states the facts read from MetaWorld 3.1.1's source for one v3 task (its XML,
the hand's start, the box its random vector is drawn from, the goal box the observation is
clipped to) and reimplements the task's logic, one env, in JAX:

- `accept(vec)`: whether MetaWorld's reset would keep a drawn random vector (several tasks
  redraw while the object is too near the goal); the scene keeps the first accepted draw.
- `place(facts, vec, qpos, qvel)`: the initial condition from the vector, applied to the state
  after MetaWorld's hand reset: joint positions and velocities (as its ``_set_obj_xyz`` /
  ``set_state`` calls do), and the per-episode positions of fixed bodies it writes into the
  model (``self.model.body("box").pos = ...``).
- `episode(facts, vec, view)`: per-episode constants read after that placement (MetaWorld reads
  some from the placed kinematics, e.g. ``_target_pos = self._get_site_pos("hole")``); must hold
  ``target_pos``, the goal MetaWorld observes and rewards against.
- `objects(view)`: MetaWorld's ``_get_pos_objects`` and ``_get_quat_objects`` (flat position(s)
  and quaternion(s), in the convention MetaWorld uses for that task: ``xquat`` is w-x-y-z,
  scipy's ``Rotation.as_quat`` is x-y-z-w).
- `success(obs, view, episode)`: ``info["success"]`` of MetaWorld's ``evaluate_state``.
- `reward(...)`: MetaWorld's v2 reward (every task ports it: `has_reward`).

Patterns many tasks share have one implementation here: `MovedBodyTask` (the vector is where a
fixed body goes), `DrawnGoalTask` (the vector is (object, goal), success a distance to the goal)
and `FreeObjectTask` (that, with a free object and MetaWorld's redraw rule).

`View` reads the physics quantities by name; a task lists the bodies, sites and geoms it reads
in `bodies`, `sites`, `geoms` (the hand, claws and pads are always there).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any, ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from openral_mjx.physics.base import Quantities

Vec = tuple[float, ...]

# MetaWorld's SawyerXYZEnv constants.
HAND_SPACE_LOW = (-0.525, 0.348, -0.0525)
HAND_SPACE_HIGH = (0.525, 1.025, 0.7)
MOCAP_QUAT = (1.0, 0.0, 1.0, 0.0)  # set_xyz_action writes it unnormalised; MuJoCo normalises
ACTION_SCALE = 1.0 / 100
FRAME_SKIP = 5
HAND_RESET_STEPS = 50
MAX_PATH_LENGTH = 500
OBS_OBJ_MAX_LEN = 14
# Bodies and sites every task's observation or logic reads.
COMMON_BODIES = ("hand", "rightclaw", "leftclaw")
COMMON_SITES = ("rightEndEffector", "leftEndEffector")


@dataclasses.dataclass(frozen=True)
class ModelFacts:
    """Static facts of the compiled task model (numpy), for `place` and `episode`.

    `rest` holds world positions in the state right after MetaWorld's hand reset (objects still
    at the model's defaults): ``rest["body:obj"]``, ``rest["site:hole"]``, ``rest["geom:objGeom"]``
    (what ``get_body_com`` / ``_get_site_pos`` / ``data.geom(...).xpos`` return there), and
    ``rest["init_tcp"]``, MetaWorld's ``init_tcp``: the tcp centre as the hand reset's last
    physics step leaves the poses (before any forward pass).
    """

    qpos_adr: Mapping[str, int]  # joint name -> first qpos index
    dof_adr: Mapping[str, int]  # joint name -> first dof index
    site_pos: Mapping[str, np.ndarray]  # site name -> model default `site_pos` (parent frame)
    rest: Mapping[str, np.ndarray]


class View:
    """Named reads of one env's `Quantities` (world frame, float32)."""

    def __init__(
        self,
        q: Quantities,
        bodies: Mapping[str, int],
        sites: Mapping[str, int],
        geoms: Mapping[str, int],
        qpos_adr: Mapping[str, int],
    ) -> None:
        self.q = q
        self._bodies, self._sites, self._geoms, self._qpos_adr = bodies, sites, geoms, qpos_adr

    def body_pos(self, name: str) -> jax.Array:
        """``data.body(name).xpos`` (= gymnasium's ``get_body_com(name)``)."""
        return self.q.body_pos[self._bodies[name]]

    def body_quat(self, name: str) -> jax.Array:
        """``data.body(name).xquat`` (w, x, y, z)."""
        return self.q.body_quat[self._bodies[name]]

    def site_pos(self, name: str) -> jax.Array:
        """``data.site(name).xpos`` (MetaWorld's ``_get_site_pos``)."""
        return self.q.site_pos[self._sites[name]]

    def geom_pos(self, name: str) -> jax.Array:
        """``data.geom(name).xpos``."""
        return self.q.geom_pos[self._geoms[name]]

    def geom_quat(self, name: str) -> jax.Array:
        """The geom's world orientation as a w-x-y-z quaternion (from ``data.geom(name).xmat``)."""
        return self.q.geom_quat[self._geoms[name]]

    def qpos(self, joint: str, size: int = 1) -> jax.Array:
        """``data.qpos`` of `joint` (`size` entries from its address; scalar for size 1)."""
        a = self._qpos_adr[joint]
        return self.q.qpos[a] if size == 1 else self.q.qpos[a : a + size]

    @property
    def hand(self) -> jax.Array:
        """MetaWorld's ``get_endeff_pos``: the ``hand`` body's position."""
        return self.body_pos("hand")

    @property
    def tcp_center(self) -> jax.Array:
        """MetaWorld's ``tcp_center``: midway between the two end-effector sites."""
        return (self.site_pos("rightEndEffector") + self.site_pos("leftEndEffector")) / 2.0


def matrix_quat(wxyz: jax.Array) -> jax.Array:
    """scipy's ``Rotation.from_matrix(R).as_quat()`` (x-y-z-w) for the rotation `wxyz`.

    scipy converts a matrix with Shepperd's method: it picks the largest of (trace, R00, R11,
    R22) and builds the quaternion from that branch, whose leading component is positive. The
    result is the rotation's quaternion with the sign that makes that component positive, so
    the same sign rule applied to `wxyz` reproduces scipy's output (up to rounding).
    """
    w, x, y, z = wxyz[0], wxyz[1], wxyz[2], wxyz[3]
    r00 = 1 - 2 * (y * y + z * z)
    r11 = 1 - 2 * (x * x + z * z)
    r22 = 1 - 2 * (x * x + y * y)
    trace = r00 + r11 + r22
    branch = jnp.argmax(jnp.stack([r00, r11, r22, trace]))
    lead = jnp.stack([x, y, z, w])[branch]
    xyzw = jnp.stack([x, y, z, w])
    return jnp.where(lead < 0, -xyzw, xyzw)


def set_obj_xyz(
    facts: ModelFacts, qpos: jax.Array, qvel: jax.Array, pos: jax.Array, joint: str = "objjoint"
) -> tuple[jax.Array, jax.Array]:
    """MetaWorld's ``_set_obj_xyz`` for a free joint: position set, its 6 velocities zeroed."""
    a, d = facts.qpos_adr[joint], facts.dof_adr[joint]
    return qpos.at[a : a + 3].set(pos), qvel.at[d : d + 6].set(0.0)


N_DRAWS = 32  # candidate random vectors per reset; P(no draw accepted) is negligible


def random_vector(task: MirrorTask, key: jax.Array) -> jax.Array:
    """The episode's MetaWorld random vector (float32) for reset key `key`: the first of
    `N_DRAWS` uniform draws from the task's ``_random_reset_space`` that `task.accept` keeps
    (MetaWorld redraws the same way). The mirror resets from it, and the `metaworld` host scene
    hands it to MetaWorld's frozen-vector reset, so seed s starts from one state on both."""
    low = jnp.asarray(task.reset_low, jnp.float32)
    high = jnp.asarray(task.reset_high, jnp.float32)
    vecs = jax.random.uniform(key, (N_DRAWS, low.shape[0]), minval=low, maxval=high)
    return vecs[jnp.argmax(jax.vmap(task.accept)(vecs))]


class MirrorTask:
    """One MetaWorld v3 task (see the module docstring). Subclasses set the class attributes
    and override the methods whose default does not match MetaWorld's task."""

    name: ClassVar[str]  # "push-v3"
    xml: ClassVar[str]  # under metaworld/assets, e.g. "sawyer_xyz/sawyer_push_v3.xml"
    hand_init_pos: ClassVar[Vec]
    reset_low: ClassVar[Vec]  # `_random_reset_space`
    reset_high: ClassVar[Vec]
    goal_low: ClassVar[Vec]  # `goal_space` (clips the goal in the observation)
    goal_high: ClassVar[Vec]
    # MetaWorld's `mocap_low` / `mocap_high` where the task sets them (default: hand_low/high)
    hand_low: ClassVar[Vec] = (-0.5, 0.40, 0.05)
    hand_high: ClassVar[Vec] = (0.5, 1.0, 0.5)
    mocap_low: ClassVar[Vec | None] = None
    mocap_high: ClassVar[Vec | None] = None
    bodies: ClassVar[tuple[str, ...]] = ()
    sites: ClassVar[tuple[str, ...]] = ()
    geoms: ClassVar[tuple[str, ...]] = ()
    # Fixed bodies whose position the reset writes per episode (`place`'s body_pos keys).
    moved_bodies: ClassVar[tuple[str, ...]] = ()
    has_reward: ClassVar[bool] = False
    # Whether MetaWorld's hand reset meets a body the reset moves (then the hand's start
    # depends on the episode and is simulated per reset, 250 physics steps, not once).
    hand_reset_per_episode: ClassVar[bool] = False
    # Control steps (of FRAME_SKIP physics steps) MetaWorld's reset simulates after moving
    # its bodies, before placing the objects (box-close and door-lock step `frame_skip` times).
    settle_steps: ClassVar[int] = 0
    # Whether MetaWorld's reset observation is read from the hand reset's last kinematics (the
    # task writes its joints and bodies without recomputing positions): then the mirror's
    # reset observation, and the first step's previous frame, show the state before `place`.
    observes_before_place: ClassVar[bool] = False

    def accept(self, vec: jax.Array) -> jax.Array:
        """Whether MetaWorld's reset keeps this random vector (default: always)."""
        del vec
        return jnp.ones((), bool)

    def place(
        self, facts: ModelFacts, vec: jax.Array, qpos: jax.Array, qvel: jax.Array
    ) -> tuple[jax.Array, jax.Array, dict[str, jax.Array]]:
        """(qpos, qvel, {moved body: position}) of the episode's start."""
        raise NotImplementedError

    def episode(self, facts: ModelFacts, vec: jax.Array, view: View) -> dict[str, jax.Array]:
        """Per-episode constants after placement; must include ``target_pos``."""
        raise NotImplementedError

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        """(positions, quaternions) as MetaWorld's ``_get_pos_objects``/``_get_quat_objects``."""
        raise NotImplementedError

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        """MetaWorld's ``info["success"]`` (bool) for the observation `obs` (39,)."""
        raise NotImplementedError

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        """MetaWorld's v2 reward (0 where not ported: see `has_reward`)."""
        del obs, view, episode, action
        return jnp.zeros((), jnp.float32)


def tolerance(
    x: jax.Array,
    upper: float,
    margin: jax.Array,
    sigmoid: str = "long_tail",
    lower: float = 0.0,
) -> jax.Array:
    """MetaWorld's ``reward_utils.tolerance(x, bounds=(lower, upper), margin, sigmoid)``: 1
    inside the bounds, else the sigmoid of d = (distance to the nearer bound) / margin, 0.1 at
    one margin out: ``long_tail`` 1 / (d^2 (1/0.1 - 1) + 1), ``gaussian`` exp(-d^2 ln(1/0.1));
    with a zero margin, the indicator of the bounds."""
    inside = (x >= lower) & (x <= upper)
    d = jnp.where(x < lower, lower - x, x - upper) / jnp.where(margin > 0, margin, 1.0)
    if sigmoid == "long_tail":
        tail = 1.0 / (d * d * (1.0 / 0.1 - 1.0) + 1.0)
    elif sigmoid == "gaussian":
        tail = jnp.exp(-0.5 * d * d * (-2.0 * jnp.log(0.1)))
    else:
        raise ValueError(f"sigmoid {sigmoid!r}: the mirror has 'long_tail' and 'gaussian'")
    return jnp.where(inside, 1.0, jnp.where(margin > 0, tail, 0.0))


def hamacher_product(a: jax.Array, b: jax.Array) -> jax.Array:
    """MetaWorld's ``reward_utils.hamacher_product``: a b / (a + b - a b), 0 where both are 0."""
    den = a + b - a * b
    return jnp.where(den > 0, a * b / jnp.where(den > 0, den, 1.0), 0.0)


def _tcp_over(
    view: View, episode: Mapping[str, Any], obj: jax.Array, xz_thresh: float
) -> jax.Array:
    """The caging rewards' x-z part: the tcp within `xz_thresh` of `obj` in x-z, its margin
    the distance from the hand reset's end (``init_tcp``) to the object's start."""
    xz = jnp.asarray([0, 2])
    xz_margin = jnp.linalg.norm(episode["obj_init_pos"][xz] - episode["init_tcp"][xz]) - xz_thresh
    return tolerance(jnp.linalg.norm(view.tcp_center[xz] - obj[xz]), xz_thresh, xz_margin)


def gripper_caging(
    view: View,
    episode: Mapping[str, Any],
    action: jax.Array,
    obj: jax.Array,
    obj_radius: float,
    pad_success_thresh: float,
    xz_thresh: float,
    effort: float = 1.0,
    density: str = "high",
    reach_radius: float = 0.01,
) -> jax.Array:
    """MetaWorld's base ``_gripper_caging_reward`` (the task's view must hold the ``leftpad``
    and ``rightpad`` bodies; `episode` ``obj_init_pos`` and ``init_tcp``): the pads either
    side of the object in y, the tcp over it in x-z, then the grip closing to `effort`.
    `density`: ``high`` averages in the caging, ``medium`` the tcp's reach to the object
    (within `reach_radius`, MetaWorld's ``object_reach_radius``), ``low`` neither."""
    start = episode["obj_init_pos"]
    pads_y = jnp.stack([view.body_pos("leftpad")[1], view.body_pos("rightpad")[1]])
    margins = jnp.abs(jnp.abs(pads_y - start[1]) - pad_success_thresh)
    lr = [
        tolerance(jnp.abs(pads_y[i] - obj[1]), pad_success_thresh, margins[i], lower=obj_radius)
        for i in range(2)
    ]
    caging = hamacher_product(
        hamacher_product(lr[0], lr[1]), _tcp_over(view, episode, obj, xz_thresh)
    )
    closed = jnp.clip(action[-1], 0.0, effort) / effort
    gripping = jnp.where(caging > 0.97, closed, 0.0)
    held = hamacher_product(caging, gripping)
    if density == "high":
        return (held + caging) / 2.0
    if density == "medium":
        reach_init = jnp.linalg.norm(start - episode["init_tcp"])
        reach = tolerance(
            jnp.linalg.norm(obj - view.tcp_center),
            reach_radius,
            jnp.abs(reach_init - reach_radius),
        )
        return (held + reach) / 2.0
    if density == "low":
        return held
    raise ValueError(f"density {density!r}: 'high', 'medium' or 'low'")


def pushing_caging(
    view: View,
    episode: Mapping[str, Any],
    obj: jax.Array,
    obj_radius: float,
    grip_margin: float,
    xz_thresh: float,
) -> jax.Array:
    """The ``_gripper_caging_reward`` that push-back, soccer, sweep and sweep-into define for
    themselves (the task's view must hold ``leftpad`` and ``rightpad``; `episode`
    ``obj_init_pos`` and ``init_tcp``): the mean of the caging (each pad within 0.05 of the
    object in y, the tcp over it in x-z) and, once caged past 0.95, the gripping (each pad
    within `obj_radius` + `grip_margin`). The grip action plays no part. Its "initial" pad
    positions are live views of MuJoCo's data in MetaWorld, so the pads' margins are read from
    the current pads."""
    pad_margin = 0.05
    left, right = view.body_pos("leftpad")[1], view.body_pos("rightpad")[1]
    deltas = (obj[1] - right, left - obj[1])
    margins = (
        jnp.abs(jnp.abs(obj[1] - right) - pad_margin),
        jnp.abs(jnp.abs(obj[1] - left) - pad_margin),
    )
    caging = [
        tolerance(d, pad_margin, m, lower=obj_radius) for d, m in zip(deltas, margins, strict=True)
    ]
    grip = [
        tolerance(d, obj_radius + grip_margin, m, lower=obj_radius)
        for d, m in zip(deltas, margins, strict=True)
    ]
    caged = hamacher_product(
        hamacher_product(caging[0], caging[1]), _tcp_over(view, episode, obj, xz_thresh)
    )
    gripping = jnp.where(caged > 0.95, hamacher_product(grip[0], grip[1]), 0.0)
    return (caged + gripping) / 2.0


def init_tcp(facts: ModelFacts) -> jax.Array:
    """MetaWorld's ``init_tcp``: the tcp centre its hand reset ends in, as its last physics
    step leaves the poses (for a task whose hand reset is the same every episode: the scene
    puts it in every such episode as ``episode["init_tcp"]``)."""
    return jnp.asarray(facts.rest["init_tcp"], jnp.float32)


def at_rest_height(facts: ModelFacts, xy: jax.Array, rest: str, dtype: Any = None) -> jax.Array:
    """`xy` at the height of ``facts.rest[rest]`` (MetaWorld's ``fix_extreme_obj_pos`` /
    ``adjust_initObjPos``: a drawn xy at the object's resting height), as
    ``jnp.asarray(..., dtype)`` makes that height."""
    return jnp.concatenate([xy, jnp.asarray(facts.rest[rest][2:3], dtype)])


class MovedBodyTask(MirrorTask):
    """A task whose random vector is the position its reset gives its one moved fixed body
    (`moved_bodies`); the joints stay as the hand reset leaves them."""

    def place(
        self, facts: ModelFacts, vec: jax.Array, qpos: jax.Array, qvel: jax.Array
    ) -> tuple[jax.Array, jax.Array, dict[str, jax.Array]]:
        (body,) = self.moved_bodies
        return qpos, qvel, {body: vec}


class DrawnGoalTask(MirrorTask):
    """A task whose random vector is (object xyz, goal xyz). The episode's ``target_pos`` is
    `target` (default: the drawn goal), its ``obj_init_pos`` `obj_init` (default: the drawn
    object position); success: the observed object (``obs[4:7]``) within `success_radius` of
    the goal."""

    success_radius: ClassVar[float]

    def obj_init(self, facts: ModelFacts, vec: jax.Array) -> jax.Array:
        """The object's initial position (MetaWorld's ``obj_init_pos``)."""
        del facts
        return vec[:3]

    def target(self, facts: ModelFacts, vec: jax.Array, view: View) -> jax.Array:
        """The goal (MetaWorld's ``_target_pos``), read after placement."""
        del facts, view
        return vec[3:6]

    def episode(self, facts: ModelFacts, vec: jax.Array, view: View) -> dict[str, jax.Array]:
        return {
            "target_pos": self.target(facts, vec, view),
            "obj_init_pos": self.obj_init(facts, vec),
        }

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        return jnp.linalg.norm(obs[4:7] - episode["target_pos"]) <= self.success_radius


class FreeObjectTask(DrawnGoalTask):
    """A `DrawnGoalTask` whose object is free: MetaWorld redraws the vector while the object's
    and the goal's xy are closer than `min_goal_distance`; by default `place` is its
    ``_set_obj_xyz`` on the free joint ``objjoint`` (position `obj_init`, velocities zeroed),
    moving no body."""

    min_goal_distance: ClassVar[float] = 0.15

    def accept(self, vec: jax.Array) -> jax.Array:
        return jnp.linalg.norm(vec[:2] - vec[3:5]) >= self.min_goal_distance

    def place(
        self, facts: ModelFacts, vec: jax.Array, qpos: jax.Array, qvel: jax.Array
    ) -> tuple[jax.Array, jax.Array, dict[str, jax.Array]]:
        qpos, qvel = set_obj_xyz(facts, qpos, qvel, self.obj_init(facts, vec))
        return qpos, qvel, {}
