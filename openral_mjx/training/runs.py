"""A `bc` or `ppo` run from start to end, as `python -m openral_mjx.finetune` runs it.

The command parses flags and prints; these functions build the scene, the configs and the
policy to start from, and run the training into its output directory. `log` receives the
progress lines (the command sends them to stderr). PPO refuses a scene whose `check_reward()`
raises (a mirror task whose reward is not ported returns 0: nothing to learn from).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import numpy as np

from openral_mjx.core.errors import ConfigError
from openral_mjx.core.files import write_json_atomic
from openral_mjx.core.options import to_dict
from openral_mjx.physics import PhysicsSettings
from openral_mjx.policies.mlp import MlpConfig, check_compatible, init_params, load_mlp, save_mlp
from openral_mjx.scenes import SCENES, Scene, make_scene
from openral_mjx.training.bc import BCConfig, collect_demos, fit, policy_config
from openral_mjx.training.evaluation import VALIDATION_SEEDS, HeldOutEvaluator
from openral_mjx.training.ppo import PPOConfig
from openral_mjx.training.run_dir import RunDir
from openral_mjx.training.session import PPOSession, Row, Schedule

Log = Callable[[str], None]


def build_scene(
    name: str, options: dict[str, Any], backend: str, threads: int | None, batch: int
) -> Scene:
    """The scene on `backend`, its buffers (`warp`) sized for `batch` envs per device."""
    SCENES.get(name)
    settings = PhysicsSettings(threads=threads, batch_size=batch)
    return make_scene(name, options, backend=backend, settings=settings)


# ---- bc ------------------------------------------------------------------------------------


def run_bc(
    scene_name: str,
    options: dict[str, Any],
    backend: str,
    out: Path,
    config: BCConfig,
    *,
    threads: int | None,
    n_demos: int,
    n_envs: int,
    max_steps: int | None,
    eval_episodes: int,
    command: str,
    log: Log,
) -> dict[str, Any]:
    """Clone the scene's expert into an `mlp` checkpoint at `out` (plus `bc.json`, the summary
    this returns, with the validation result when `eval_episodes` > 0)."""
    for name, value in (("n_demos", n_demos), ("n_envs", n_envs)):
        if value < 1:
            raise ConfigError(f"{name} must be a positive integer, got {value}")
    if eval_episodes < 0:
        raise ConfigError(f"eval_episodes must be >= 0, got {eval_episodes}")
    if out.exists() and not out.is_dir():
        raise ConfigError(f"--out {str(out)!r} is a file; give a directory")
    scene = build_scene(scene_name, options, backend, threads, n_envs)
    steps = max_steps or scene.max_steps
    t0 = time.perf_counter()
    log(f"demonstrations: {n_demos} expert episodes on {backend} ...")
    demos = collect_demos(scene, n_episodes=n_demos, n_envs=n_envs, max_steps=steps)
    demo_s = time.perf_counter() - t0
    log(
        f"demonstrations: {demos.n_successful}/{demos.n_episodes} successful, "
        f"{len(demos.obs):,} transitions, {demo_s:.1f} s ({demos.env_steps_per_s:,.0f} steps/s)"
    )
    mlp_config = policy_config(scene, demos, config)

    def on_epoch(epoch: int, loss: float) -> None:
        log(f"bc epoch {epoch}/{config.epochs}: loss {loss:.4f}")

    t1 = time.perf_counter()
    params, history = fit(mlp_config, demos, config, on_epoch)
    fit_s = time.perf_counter() - t1
    mlp_config = dataclasses.replace(
        mlp_config,
        metadata={
            **mlp_config.metadata,
            "trained": {"method": "bc", "demos": demos.n_successful, "final_loss": history[-1]},
        },
    )
    save_mlp(out, mlp_config, jax.device_get(params))
    summary: dict[str, Any] = {
        "scene": scene.name,
        "backend": backend,
        "demo_episodes": demos.n_episodes,
        "demo_successful": demos.n_successful,
        "transitions": len(demos.obs),
        "demo_s": demo_s,
        "fit_s": fit_s,
        "losses": history,
        "command": command,
    }
    if eval_episodes:
        evaluator = HeldOutEvaluator(
            scene, mlp_config, n_episodes=eval_episodes, n_envs=n_envs, max_steps=steps
        )
        r = evaluator(params)
        summary["validation"] = {**dataclasses.asdict(r), "first_seed": VALIDATION_SEEDS}
    write_json_atomic(out / "bc.json", summary)
    return summary


# ---- ppo -----------------------------------------------------------------------------------


def scratch_config(
    scene: Scene, hidden: tuple[int, ...], activation: str, action_scale: float = 0.05
) -> MlpConfig:
    """A fresh policy: actions relative to the joints (where the scene reads them), `u` =
    `action_scale` of each control range (5%: a small step for a position servo)."""
    if not action_scale > 0:
        raise ConfigError(f"action_scale must be > 0, got {action_scale}")
    low, high = (np.asarray(x) for x in scene.action_bounds())
    return MlpConfig(
        obs_size=scene.observation_size,
        action_size=scene.action_size,
        action_offset=(0.0,) * scene.action_size,
        action_scale=tuple(float(x) for x in action_scale * (high - low)),
        action_base_index=scene.action_obs_index(),
        hidden=hidden,
        activation=activation,
        metadata={
            "scene": scene.name,
            "robot": scene.robot_name,
            "scene_options": to_dict(scene.options),
        },
    )


@dataclasses.dataclass(frozen=True)
class NewPolicy:
    """What a new PPO run starts from: an `mlp` checkpoint, or a fresh network."""

    init: Path | None = None
    hidden: tuple[int, ...] = (256, 256, 256)  # fresh network only
    activation: str = "silu"  # fresh network only
    seed: int = 0
    action_scale: float = 0.05  # fresh network only: see `scratch_config`


@dataclasses.dataclass
class PPORun:
    """A PPO run ready to train: `settings` is what `run.json` holds."""

    run_dir: RunDir
    settings: dict[str, Any]
    scene: Scene
    num_updates: int
    session: PPOSession
    init_policy: dict[str, Any] | None
    resume: bool

    def run(self, on_row: Callable[[Row], None] | None = None) -> Row:
        """Train to the end (see `PPOSession.run`), handing every metrics row to `on_row`;
        returns the summary row."""
        if on_row is not None:
            self.session.on_row = on_row
        return self.session.run(self.init_policy, resume=self.resume)


def prepare_ppo(
    run_dir: RunDir,
    settings: dict[str, Any],
    *,
    ppo: dict[str, Any] | None,
    start: NewPolicy | None,
    threads: int | None,
    command: str,
) -> PPORun:
    """A new run (`ppo`: `PPOConfig` fields, `max_steps` None for the scene's; `start`: the
    initial policy) into a new `run_dir`, or, with both None, the run `settings` were loaded
    from (resumed; `settings` may extend its `num_timesteps`)."""
    resume = ppo is None
    if int(settings["num_timesteps"]) < 1:
        n = settings["num_timesteps"]
        raise ConfigError(f"num_timesteps must be a positive integer, got {n}")
    n_envs = settings["ppo"]["n_envs"] if resume else ppo["n_envs"]
    batch = max(n_envs, settings["schedule"]["eval_n_envs"])
    scene = build_scene(
        settings["scene"], settings["scene_options"], settings["backend"], threads, batch
    )
    check_reward = getattr(scene, "check_reward", None)
    if check_reward is not None:  # a scene whose reward is undefined here refuses (ConfigError)
        try:
            check_reward()
        except ConfigError:
            scene.close()
            raise
    init_policy = None
    if resume:
        fields = {**settings["ppo"], "critic_hidden": tuple(settings["ppo"]["critic_hidden"])}
        ppo_config = PPOConfig(**fields)
        mlp_config = MlpConfig.from_json(settings["mlp"])
    else:
        assert start is not None
        fields = {**ppo, "max_steps": ppo.get("max_steps") or scene.max_steps}
        if fields.get("update_normalizer") is None:  # default: learn statistics from scratch only
            fields["update_normalizer"] = start.init is None
        ppo_config = PPOConfig(**fields)
        if start.init is not None:
            mlp_config, init_policy = load_mlp(start.init)
            check_compatible(mlp_config, scene, f"--init {str(start.init)!r}")
        else:
            mlp_config = scratch_config(scene, start.hidden, start.activation, start.action_scale)
            init_policy = init_params(mlp_config, jax.random.PRNGKey(start.seed + 1))
    num_updates = -(-int(settings["num_timesteps"]) // ppo_config.steps_per_update)
    schedule = Schedule(num_updates=num_updates, **settings["schedule"])
    if resume:
        run_dir.save_settings(settings)
    else:
        settings["ppo"] = dataclasses.asdict(ppo_config)
        settings["mlp"] = mlp_config.to_json()
        settings["command"] = command
        run_dir.create(settings)
    session = PPOSession(scene, run_dir, mlp_config, ppo_config, schedule)
    return PPORun(run_dir, settings, scene, num_updates, session, init_policy, resume)
