"""A MetaWorld v3 task as a gym-style env (runs in a worker of the ``metaworld`` environment).

MetaWorld 3.1.1's Sawyer env for one task (``reach-v3``, ...), built from its class in
`metaworld.env_dict.ALL_V3_ENVIRONMENTS` and set up as MetaWorld's own goal-observable and
goal-hidden constructors do (task set, randomisation unfrozen), except that the random vector
(object and goal positions) comes from the env's own seeded generator: MetaWorld draws it in
`_get_state_rand_vec` from ``self.np_random`` when ``seeded_rand_vec`` is set, and `seed(s)`
re-creates that generator. Every reset re-seeds it with the episode's seed and first puts the
MuJoCo data back to the model's defaults (`mj_resetData`: controls, warm starts, time), so seed
s gives the same initial state whatever this env ran before and whichever worker runs it.

Observation: ``obs``, MetaWorld's 39 floats (hand position, gripper opening, object poses,
the same for the previous step, goal position; the goal is zeros with ``goal_observable=False``
as in MetaWorld's ML benchmarks), ``agent_pos`` = its first 4 (lerobot's MetaWorld
``agent_pos``), with ``image_size > 0`` ``pixels`` (lerobot's camera: ``corner2`` moved to
(0.75, 0.075, 0.7), flipped upright), and with ``expert`` the action of MetaWorld's scripted
policy for the task (`metaworld.policies.ENV_POLICY_MAP`) at this observation, computed from
the goal-observable observation (``expert_action``, read by ``--policy metaworld-expert``).
Action: 4-D (hand xyz delta, gripper) in [-1, 1]. Success: ``info["success"]``; the episode
ends there, and is truncated at MetaWorld's ``max_path_length`` (500). Reset info carries the
episode factors: the object's initial position and the goal position.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np

CAMERA = "corner2"
CAMERA_POS = (0.75, 0.075, 0.7)  # lerobot's (and the paper lerobot cites) corner2 position
FACTORS = ("obj_x", "obj_y", "obj_z", "goal_x", "goal_y", "goal_z")


def task_names() -> list[str]:
    """MetaWorld's 50 v3 tasks, in its order."""
    from metaworld.env_dict import ALL_V3_ENVIRONMENTS

    return list(ALL_V3_ENVIRONMENTS)


def suites() -> dict[str, list[str]]:
    """MetaWorld's benchmarks as task lists: MT10, MT50, ML45 train and test."""
    from metaworld import env_dict

    return {
        "mt10": list(env_dict.MT10_V3),
        "mt50": list(env_dict.MT50_V3),
        "ml45-train": list(env_dict.ML45_V3["train"]),
        "ml45-test": list(env_dict.ML45_V3["test"]),
    }


class MetaWorldEnv:
    """One MetaWorld v3 task (see module docstring)."""

    def __init__(
        self,
        task: str = "reach-v3",
        goal_observable: bool = True,
        image_size: int = 0,
        expert: bool = True,
    ) -> None:
        import mujoco
        from metaworld.env_dict import ALL_V3_ENVIRONMENTS
        from metaworld.policies import ENV_POLICY_MAP

        if task not in ALL_V3_ENVIRONMENTS:
            raise ValueError(f"unknown MetaWorld task {task!r}")
        # the scripted policies warn at every step where their gains saturate an action
        warnings.filterwarnings("ignore", message=r"Constant\(s\) may be too high")
        self._mujoco = mujoco
        _fit_weld_data(mujoco)
        kwargs: dict[str, Any] = {}
        if image_size > 0:
            kwargs = dict(
                render_mode="rgb_array", camera_name=CAMERA, width=image_size, height=image_size
            )
        env = ALL_V3_ENVIRONMENTS[task](**kwargs)
        env._set_task_called = True  # a task without a frozen random vector (see module doc)
        env._partially_observable = not goal_observable
        env.__dict__.pop("sawyer_observation_space", None)  # cached; depends on the line above
        env._freeze_rand_vec = False
        env.seeded_rand_vec = True
        if image_size > 0:
            env.model.cam_pos[env.model.camera(CAMERA).id] = CAMERA_POS
        self.env = env
        self.task = task
        self.image_size = image_size
        self.policy = ENV_POLICY_MAP[task]() if expert else None
        self.max_steps = int(env.max_path_length)

    def versions(self) -> dict[str, str]:
        """The MetaWorld and MuJoCo this worker runs (MetaWorld's pinned one, or another put
        first on its path)."""
        from importlib.metadata import version

        return {"metaworld": version("metaworld"), "mujoco": self._mujoco.__version__}

    def _obs(self, raw: np.ndarray) -> dict[str, np.ndarray]:
        obs = np.asarray(raw, np.float64)
        out = {"obs": obs.astype(np.float32), "agent_pos": obs[:4].astype(np.float32)}
        if self.image_size > 0:
            out["pixels"] = np.ascontiguousarray(np.flip(self.env.render(), (0, 1)))
        if self.policy is not None:
            full = obs.copy()
            full[-3:] = self.env._get_pos_goal()  # the expert reads the goal, hidden or not
            action = self.policy.get_action(full)
            out["expert_action"] = np.clip(np.asarray(action, np.float32), -1.0, 1.0)
        return out

    def _factors(self) -> dict[str, float]:
        values = []
        for vec in (self.env.obj_init_pos, self.env._target_pos):
            v = np.full(3, np.nan) if vec is None else np.asarray(vec, np.float64).ravel()
            values.extend((list(v[:3]) + [np.nan] * 3)[:3])
        return {name: float(v) for name, v in zip(FACTORS, values, strict=True)}

    def reset(self, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        """A new episode from `seed`, or with ``options={"rand_vec": [...]}`` from that random
        vector (MetaWorld's frozen-vector path: the `metaworld` scene hands it the vector it
        draws for seed s, the mirror's, so both scenes start seed s from one state)."""
        env = self.env
        self._mujoco.mj_resetData(env.model, env.data)
        env.seed(0 if seed is None else int(seed) % 2**32)
        vec = (options or {}).get("rand_vec")
        if vec is not None:
            env._last_rand_vec = np.asarray(vec, np.float64)
            env._freeze_rand_vec = True
        try:
            raw, _ = env.reset()
        finally:
            env._freeze_rand_vec = False
        return self._obs(raw), {"success": False, "factors": self._factors()}

    def state(self) -> dict[str, np.ndarray]:
        """Joint positions and velocities, mocap target and the positions MetaWorld's task logic
        reads (hand, tcp centre, the observation's objects): what agreement tests compare."""
        env = self.env
        return {
            "qpos": env.data.qpos.copy(),
            "qvel": env.data.qvel.copy(),
            "mocap_pos": env.data.mocap_pos.copy(),
            "body_pos": env.model.body_pos.copy(),
            "tcp_center": np.asarray(env.tcp_center, np.float64).copy(),
            "target_pos": np.asarray(env._target_pos, np.float64).copy(),
        }

    def rollout(
        self,
        rand_vec: np.ndarray | None,
        actions: np.ndarray | None = None,
        max_steps: int = 500,
        qpos: np.ndarray | None = None,
        qvel: np.ndarray | None = None,
    ) -> dict[str, Any]:
        """One episode in this worker: from `rand_vec` (then, if given, the joint state `qpos`,
        `qvel`: another simulator's reset state), playing `actions` (T, 4) open loop, or the
        scripted expert closed loop when None, until success (expert) or the end. Returns the
        observations (T + 1, 39), per-step success and the step of first success (-1)."""
        obs, _ = self.reset(options={"rand_vec": rand_vec})
        if qpos is not None:
            self.env.set_state(np.asarray(qpos, np.float64), np.asarray(qvel, np.float64))
            self.env._prev_obs = self.env._get_curr_obs_combined_no_goal()
            obs = self._obs(self.env._get_obs())
        raw = [obs["obs"]]
        successes, played = [], []
        steps = max_steps if actions is None else len(actions)
        for t in range(steps):
            a = obs["expert_action"] if actions is None else actions[t]
            played.append(a)
            obs, _, success, truncated, _ = self.step(a)
            raw.append(obs["obs"])
            successes.append(success)
            if (actions is None and success) or truncated:
                break
        hits = np.flatnonzero(successes)
        return {
            "obs": np.stack(raw),
            "actions": np.asarray(played, np.float32).reshape(-1, 4),
            "success": np.asarray(successes, bool),
            "first_success": int(hits[0]) if hits.size else -1,
        }

    def expert_trace(self, rand_vec: np.ndarray, steps: int) -> dict[str, np.ndarray]:
        """`steps` steps of the scripted expert from `rand_vec` (on past success), in one call:
        per step the action, MetaWorld's `step` reward and observation, and the joint state
        and body positions it ends in (what reward checks put into the mirror's physics)."""
        obs, _ = self.reset(options={"rand_vec": rand_vec})
        trace: dict[str, list] = {}
        for _ in range(steps):
            action = obs["expert_action"]
            obs, reward, _, _, _ = self.step(action)
            state = self.state()
            row = {"action": action, "reward": reward, "obs": obs["obs"]}
            row.update({k: state[k] for k in ("qpos", "qvel", "body_pos")})
            for k, v in row.items():
                trace.setdefault(k, []).append(v)
        return {k: np.asarray(v) for k, v in trace.items()}

    def step(self, action: np.ndarray) -> tuple[dict, float, bool, bool, dict]:
        a = np.clip(np.asarray(action, np.float32), -1.0, 1.0)
        raw, reward, _, truncated, info = self.env.step(a)
        success = bool(info.get("success", 0.0))
        return self._obs(raw), float(reward), success, bool(truncated), {"success": success}

    def close(self) -> None:
        self.env.close()


def make(**kwargs: Any) -> MetaWorldEnv:
    return MetaWorldEnv(**kwargs)


class MetaWorldExpert:
    """MetaWorld's scripted policy for one task, over a batch of observations (for the
    `metaworld_mjx` mirror, whose observations come from JAX)."""

    def __init__(self, task: str) -> None:
        from metaworld.policies import ENV_POLICY_MAP

        if task not in ENV_POLICY_MAP:
            raise ValueError(f"no MetaWorld scripted policy for task {task!r}")
        warnings.filterwarnings("ignore", message=r"Constant\(s\) may be too high")
        self.policy = ENV_POLICY_MAP[task]()

    def act(self, obs: np.ndarray) -> np.ndarray:
        """Actions (n, 4) in [-1, 1] for observations (n, 39) (goal included)."""
        obs = np.asarray(obs, np.float64).reshape(-1, 39)
        out = np.stack([self.policy.get_action(o) for o in obs]) if len(obs) else np.zeros((0, 4))
        return np.clip(out, -1.0, 1.0).astype(np.float32)


def make_expert(task: str) -> MetaWorldExpert:
    return MetaWorldExpert(task)


# MetaWorld's `reset_mocap_welds` writes these 11 numbers as each weld's whole `eq_data` row
# before any simulation (anchor, relative pose with quaternion (-1, 0, 0, 0), torque scale 5):
# MuJoCo before 4.0 has 11 per constraint, 4.0 has 12. The mirror's model gets them too.
WELD_DATA = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 5.0)


def _fit_weld_data(mujoco: Any) -> None:
    """Under a MuJoCo whose weld data is wider than MetaWorld's row (4.0, put first on the
    worker's path to run MetaWorld's code on the mirror's engine), write MetaWorld's numbers
    into the row's first 11 entries and leave the rest at the model's values; unchanged
    otherwise."""
    from metaworld import sawyer_xyz_env

    if int(getattr(mujoco, "mjNEQDATA", len(WELD_DATA))) == len(WELD_DATA):
        return

    def reset_mocap_welds(self: Any) -> None:
        model = self.model
        if model.nmocap > 0 and model.eq_data is not None:
            for i in range(model.eq_data.shape[0]):
                if model.eq_type[i] == mujoco.mjtEq.mjEQ_WELD:
                    model.eq_data[i, : len(WELD_DATA)] = WELD_DATA

    sawyer_xyz_env.SawyerMocapBase.reset_mocap_welds = reset_mocap_welds
