"""Evaluate a policy on a scene: roll out seeds with the runner and aggregate an `EvalReport`."""

from __future__ import annotations

import dataclasses
import datetime as dt
import importlib.metadata
import platform
from collections.abc import Callable, Mapping
from typing import Any

import jax
import numpy as np

import openral_mjx
from openral_mjx.errors import ConfigError
from openral_mjx.options import to_dict
from openral_mjx.physics import PhysicsSettings
from openral_mjx.policies import make_policy
from openral_mjx.rollout import RunTiming, check_counts, run_seeds
from openral_mjx.scenes import Scene, make_scene
from openral_mjx.schema import EpisodeResult, EvalReport, TaskRow
from openral_mjx.stats import wilson_interval

_PACKAGES = ("jax", "jaxlib", "mujoco", "mujoco-mjx", "flax", "numpy")


def package_versions() -> dict[str, str]:
    """Versions of Python and the packages that decide a result (source-tree runs included)."""
    out = {"python": platform.python_version(), "openral_mjx": openral_mjx.__version__}
    for name in _PACKAGES:
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


def device_description(scene: Scene) -> str:
    """What ran the physics: the JAX devices for `mjx`/`warp`, the CPU thread pool for `c`."""
    if scene.backend.name == "c":
        return f"cpu: MuJoCo C, {scene.backend.describe()['threads']} threads"
    devices = scene.backend.devices()
    return f"{devices[0].platform}: {devices[0].device_kind} x{len(devices)}"


def episode_results(
    arrays: Mapping[str, np.ndarray],
    seeds: np.ndarray,
    timing: RunTiming,
    control_dt: float,
    metadata: Mapping[str, Any],
) -> list[EpisodeResult]:
    """Turn the runner's per-env arrays into `EpisodeResult`s (latency from chunk timings)."""
    budget_ms = 1000 * control_dt
    chunk_ms = [1000 * s / timing.scan_steps for s in timing.chunk_s]
    max_ms = max(chunk_ms)
    results = []
    for i, seed in enumerate(seeds):
        mean_ms = chunk_ms[i // timing.n_envs]
        steps = int(arrays["steps"][i])
        results.append(
            EpisodeResult(
                success=bool(arrays["success"][i]),
                steps=steps,
                total_reward=float(arrays["total_reward"][i]),
                mean_step_latency_ms=mean_ms,
                max_step_latency_ms=max_ms,
                latency_budget_ms=budget_ms,
                budget_violations=steps if mean_ms > budget_ms else 0,
                metadata={
                    **metadata,
                    "seed": int(seed),
                    "diverged": bool(arrays["diverged"][i]),
                    "first_success_step": int(arrays["first_success_step"][i]),
                },
            )
        )
    return results


def evaluate(
    scene: str | Scene = "tabletop_push",
    policy: str = "scripted",
    *,
    n_envs: int = 1024,
    n_episodes: int | None = None,
    seed: int = 0,
    max_steps: int | None = None,
    backend: str = "auto",
    threads: int | None = None,
    contacts_per_env: int | None = None,
    options: Mapping[str, Any] | None = None,
    command: str = "",
    on_chunk: Callable[[int, int], None] | None = None,
) -> EvalReport:
    """Evaluate `policy` on seeds `seed .. seed + n_episodes - 1` and return the report.

    Raises `ConfigError` for unknown names, bad options and non-positive counts.
    """
    n_episodes = n_envs if n_episodes is None else n_episodes
    check_counts(n_envs, n_episodes, 1 if max_steps is None else max_steps)
    if seed < 0:
        raise ConfigError(f"seed must be >= 0, got {seed}")
    if isinstance(scene, str):
        settings = PhysicsSettings(threads=threads, batch_size=n_envs)
        if contacts_per_env is not None:
            settings = dataclasses.replace(settings, contacts_per_env=contacts_per_env)
        scene = make_scene(scene, options, backend=backend, settings=settings)
    pol = make_policy(policy, scene)
    steps = scene.max_steps if max_steps is None else max_steps
    seeds = np.arange(seed, seed + n_episodes, dtype=np.int64)
    params, _ = pol.init(
        jax.random.PRNGKey(seed), jax.ShapeDtypeStruct((scene.observation_size,), np.float32)
    )
    arrays, timing = run_seeds(
        scene, pol, params, seeds=seeds, n_envs=n_envs, max_steps=steps, on_chunk=on_chunk
    )
    meta = {
        "scene": scene.name,
        "task": scene.task,
        "robot": scene.robot_name,
        "policy": policy,
        "backend": scene.backend.name,
    }
    episodes = episode_results(arrays, seeds, timing, scene.control_dt, meta)
    successes = int(arrays["success"].sum())
    low, high = wilson_interval(successes, n_episodes)
    simulated = len(timing.chunk_s) * timing.n_envs * timing.scan_steps
    return EvalReport(
        scene=scene.name,
        task=scene.task,
        robot=scene.robot_name,
        policy=policy,
        backend=scene.backend.name,
        device=device_description(scene),
        n_episodes=n_episodes,
        n_envs=timing.n_envs,
        seed=seed,
        max_steps=steps,
        successes=successes,
        success_rate=successes / n_episodes,
        ci_low=low,
        ci_high=high,
        confidence=0.95,
        ci_method="wilson",
        diverged=int(arrays["diverged"].sum()),
        per_task=[TaskRow(scene.task, n_episodes, successes, successes / n_episodes, low, high)],
        env_steps_per_s=simulated / timing.run_s,
        episodes_per_s=n_episodes / timing.run_s,
        compile_s=timing.compile_s,
        run_s=timing.run_s,
        control_dt_s=scene.control_dt,
        options={**to_dict(scene.options), "backend": scene.backend.describe()},
        versions=package_versions(),
        command=command,
        created_at=dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        episodes=episodes,
    )


__all__ = ["evaluate", "package_versions"]
