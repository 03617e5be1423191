"""The envs of one worker: gym-style envs from one factory, stepped in turn (runs in a worker).

A factory returns an env with the gymnasium API: ``reset(seed=int, options=dict) -> (obs,
info)`` and ``step(action) -> (obs, reward, terminated, truncated, info)``; success is
``info["is_success"]`` (or ``info["success"]``); a step whose ``info["diverged"]`` is true
ends the episode as diverged (its physics blew up: a failure, reported as such). Observations
are a dict of arrays (or one array, named ``obs``) that must match the declared shapes, so
every reply has fixed shapes.
Declared episode factors are read from the reset's ``info["factors"]`` (name -> float; 0 where
missing) and returned with every reset as ``factors``, one row per env.
An env that raises fails alone: its slot reports the error and the worker carries on.
Standard library and numpy only (plus whatever the factory imports).
"""

from __future__ import annotations

import time
import traceback
from typing import Any

import numpy as np

from openral_mjx.host.worker import load


class GymBatch:
    """`n` envs built by `factory(**kwargs)`, created on their first reset.

    Args:
        factory: ``module:callable`` importable in this worker's environment.
        kwargs: keyword arguments of the factory (JSON types).
        n: envs in this worker.
        observation: declared observation, name -> (shape, dtype string).
        factors: names of the episode factors a reset reports (see module docstring).
    """

    def __init__(
        self,
        factory: str,
        kwargs: dict[str, Any],
        n: int,
        observation: dict[str, Any],
        factors: list[str] | None = None,
    ) -> None:
        self._make = load(factory)
        self._kwargs = kwargs
        self._envs: list[Any] = [None] * n
        self._spec = {k: (tuple(s), np.dtype(d)) for k, (s, d) in observation.items()}
        self._factor_names = list(factors or [])
        self._factors = np.zeros((n, len(self._factor_names)), np.float32)

    def _obs(self, raw: Any) -> dict[str, np.ndarray]:
        if not isinstance(raw, dict):
            raw = {"obs": raw}
        out = {}
        for name, (shape, dtype) in self._spec.items():
            if name not in raw:
                raise KeyError(f"observation has no {name!r}; it has {sorted(raw)}")
            value = np.asarray(raw[name])
            if value.shape != shape:
                raise ValueError(f"observation {name!r} has shape {value.shape}, not {shape}")
            out[name] = value.astype(dtype, copy=False)
        return out

    def _blank(self) -> dict[str, np.ndarray]:
        return {name: np.zeros(shape, dtype) for name, (shape, dtype) in self._spec.items()}

    def _run(self, slots: list[int], fn) -> dict[str, Any]:
        obs, reward, terminated, success, diverged, errors = [], [], [], [], [], []
        start = time.perf_counter()
        for i in slots:
            try:
                o, r, t, s, d = fn(i)
                obs.append(self._obs(o))
                reward.append(r)
                terminated.append(t or d)
                success.append(s and not d)
                diverged.append(d)
                errors.append(None)
            except Exception as e:
                obs.append(self._blank())
                reward.append(0.0)
                terminated.append(True)
                success.append(False)
                diverged.append(False)
                last = traceback.format_exc().strip().splitlines()[-3:]
                errors.append(f"{type(e).__name__}: {e} ({' | '.join(last)})")
        return {
            "obs": {k: np.stack([o[k] for o in obs]) for k in self._spec},
            "reward": np.asarray(reward, np.float32),
            "terminated": np.asarray(terminated, bool),
            "success": np.asarray(success, bool),
            "diverged": np.asarray(diverged, bool),
            "errors": errors,
            "busy_s": time.perf_counter() - start,  # in the envs' own code (for overhead figures)
        }

    def build(self) -> None:
        """Create every env now (so that the evaluator can time it apart from the episodes)."""
        for i, env in enumerate(self._envs):
            if env is None:
                self._envs[i] = self._make(**self._kwargs)

    def reset(self, slots: list[int], seeds: list[int], options: list[dict]) -> dict[str, Any]:
        """Reset the envs at local `slots` with a seed and options each."""
        args = dict(zip(slots, zip(seeds, options, strict=True), strict=True))

        def one(i: int):
            if self._envs[i] is None:
                self._envs[i] = self._make(**self._kwargs)
            seed, opts = args[i]
            self._factors[i] = 0.0
            obs, info = self._envs[i].reset(seed=int(seed), options=opts)
            values = info.get("factors") or {}
            self._factors[i] = [float(values.get(k, 0.0)) for k in self._factor_names]
            success = bool(info.get("is_success", info.get("success", False)))
            return obs, 0.0, False, success, False

        out = self._run(slots, one)
        if self._factor_names:
            out["factors"] = self._factors[slots]
        return out

    def step(self, slots: list[int], actions: np.ndarray) -> dict[str, Any]:
        """Step the envs at local `slots`, one action row each."""
        rows = dict(zip(slots, actions, strict=True))

        def one(i: int):
            obs, reward, terminated, truncated, info = self._envs[i].step(rows[i])
            success = bool(info.get("is_success", info.get("success", False)))
            done = bool(terminated or truncated or success)
            return obs, float(reward), done, success, bool(info.get("diverged", False))

        return self._run(slots, one)

    def close(self) -> None:
        for env in self._envs:
            if env is not None and hasattr(env, "close"):
                env.close()
        self._envs = [None] * len(self._envs)
