"""A gym-style CPU simulator as a scene of the runner, through one host callback per step.

`HostScene.reset` / `step` follow the scene contract (one env, pure JAX): each is a
`jax.pure_callback` that vmap hands the whole batch at once (`vmap_method="broadcast_all"`), so
one control step of N envs is one call into `EnvBatch`, which steps the N envs in worker
processes (see `openral_mjx.host.batch`). The simulator's state lives in the workers, keyed by
env slot (the env's position in the batch); the JAX state carries the slot, the observation
(a dict of fixed-shape arrays, or with `HostSceneSpec.flat_obs` their concatenation), reward,
done, success and an error code. Every chunk of the runner starts with a reset of all slots, so
workers started once serve every chunk.

Determinism: seed s reaches the env as its reset seed (drawn from the episode's reset key) and,
for simulators with a fixed list of initial states, as init state ``s mod n_init_states``; a
scene may also draw a vector in JAX from the reset key (`HostSceneSpec.reset_draw`, e.g. its
mirror's random draw) that the env resets from, so seed s starts where the mirror's does.
Episode factors (`batch.factors`, e.g. initial object and goal positions) come from each
env's reset and ride along in the state's info, where `episode_factors` reads them.
An env whose physics blows up (its step reports ``info["diverged"]``) ends as a diverged
episode, a failure marked as such. A finished env is not stepped again; it returns its last
observation. A worker that crashes or hangs fails the episodes of its slots (the error text
lands in their metadata) and the rest of the batch goes on.
"""

from __future__ import annotations

import dataclasses
from collections import Counter
from collections.abc import Callable, Mapping
from types import ModuleType
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from openral_mjx.core.errors import ConfigError
from openral_mjx.core.options import check
from openral_mjx.host.batch import BatchConfig, EnvBatch
from openral_mjx.host.envs import worker_versions
from openral_mjx.host.pool import RemoteError, WorkerFailure, host_callback
from openral_mjx.scenes.base import Scene, State, obs_slices


@dataclasses.dataclass(frozen=True)
class HostSceneSpec:
    """Everything the JAX side must know statically about a host simulator.

    Attributes:
        name, task, robot: reported names.
        batch: what the workers run (see `BatchConfig`).
        action_low, action_high: per-dimension action limits (actions are clipped to them).
        control_dt: seconds per control step.
        max_steps: default episode length.
        n_init_states: fixed initial states to pick from by seed (0: the env's own sampling).
        reset_options: extra options passed to every env reset.
        reset_draw: a float vector drawn in JAX from the episode's reset key, handed to the
            env's reset as option `reset_draw_option` (a list of floats); None: no draw.
        reset_draw_option: that option's name.
        instruction: the task in natural language (see `Scene.instruction`; empty: the
            fallback from the task name).
        flat_obs: observe one flat float32 vector, the observation's entries (all 1-D)
            concatenated in their order, as a mirror without cameras does: then policies that
            need a flat vector (mlp) run on the host scene too.
    """

    name: str
    task: str
    robot: str
    batch: BatchConfig
    action_low: tuple[float, ...]
    action_high: tuple[float, ...]
    control_dt: float
    max_steps: int
    n_init_states: int = 0
    reset_options: dict[str, Any] = dataclasses.field(default_factory=dict)
    instruction: str = ""
    reset_draw: Callable[[jax.Array], jax.Array] | None = None
    reset_draw_option: str = "rand_vec"
    flat_obs: bool = False

    def __post_init__(self) -> None:
        if self.flat_obs and any(len(s) != 1 for s, _ in self.batch.observation.values()):
            raise ValueError(f"flat_obs needs 1-D entries, not {self.batch.observation}")


@dataclasses.dataclass(frozen=True)
class HostOptions:
    """Worker processes of a host scene (`openral_mjx.host`).

    Attributes:
        n_workers: worker processes (each steps its share of the envs in turn); None: one per
            core, at most one per env.
        step_timeout_s: a worker that takes longer for one batched step is killed and its envs
            fail (the error is in their metadata).
        reset_timeout_s: the same for a reset (the first one also builds the envs).
    """

    n_workers: int | None = None
    step_timeout_s: float = 60.0
    reset_timeout_s: float = 600.0

    def batch_config(
        self,
        factory: str,
        kwargs: dict[str, Any],
        observation: dict[str, tuple[tuple[int, ...], str]],
        action_size: int,
        env: dict[str, str] | None = None,
        path_first: tuple[str, ...] = (),
    ) -> BatchConfig:
        """The workers' configuration with these options (the interpreter is set later)."""
        return BatchConfig(
            python="",
            factory=factory,
            kwargs=kwargs,
            observation=observation,
            action_size=action_size,
            n_workers=self.n_workers,
            step_timeout_s=self.step_timeout_s,
            reset_timeout_s=self.reset_timeout_s,
            env=dict(env or {}),
            path_first=path_first,
        )

    def __post_init__(self) -> None:
        if self.n_workers is not None:
            check(self.n_workers >= 1, f"option n_workers={self.n_workers}: must be >= 1")
        for name in ("step_timeout_s", "reset_timeout_s"):
            value = getattr(self, name)
            check(value > 0, f"option {name}={value}: must be > 0")


class HostBackend:
    """Where a host scene's physics runs: simulator worker processes on this machine's CPU."""

    name = "host"
    exportable = False  # host callbacks cannot be serialized (see `export_cache`)
    layout_invariant = False  # no re-simulation of single episodes (videos) for host scenes

    def __init__(self, spec: HostSceneSpec, batch: EnvBatch, python: str, env_name: str) -> None:
        self._spec, self._batch, self._python, self._env_name = spec, batch, python, env_name

    @property
    def control_dt(self) -> float:
        return self._spec.control_dt

    @property
    def max_batch(self) -> int | None:
        return None

    def devices(self) -> list[jax.Device]:
        """The host CPU: the loop around the callbacks stays where the simulator runs."""
        return [jax.devices("cpu")[0]]

    def warm_up(self) -> None:
        """Nothing to build: workers start in `HostScene.prepare`."""

    def n_workers(self, n_envs: int) -> int:
        return self._batch.workers_for(n_envs)

    def device_label(self) -> str:
        n = self._batch.n or 1
        where = " on Ray" if self._batch.nodes else ""
        return f"cpu: {self.n_workers(n)} worker processes{where} ({self._env_name} environment)"

    def worker_versions(self) -> dict[str, str]:
        """The simulator's package versions in the workers' environment (`envs.worker_versions`),
        prefixed ``worker `` for the report's `versions`."""
        found = worker_versions(self._python, self._spec.batch.path_first)
        return {f"worker {name}": version for name, version in found.items()}

    def describe(self) -> dict[str, Any]:
        b = self._spec.batch
        return {
            "name": self.name,
            "environment": self._env_name,
            "python": self._python,
            "factory": b.factory,
            "workers": self.n_workers(self._batch.n or 1),
            "step_timeout_s": b.step_timeout_s,
            # on Ray: how many workers ran on each node (by IP), the last layout's, and how
            # often a worker's lost actor was replaced (its episodes replayed on the new one)
            **(
                {"ray_nodes": dict(Counter(self._batch.nodes)), "ray_retries": self._batch.retries}
                if self._batch.nodes
                else {}
            ),
        }


class HostScene(Scene):
    """A scene whose envs are gym-style simulators in worker processes (see module doc).

    Args:
        spec: the simulator, its observation and action layout.
        options: the scene's options (recorded in reports).
        env_name: worker environment (see `openral_mjx.host.envs`).
        python: its interpreter (resolved by the caller, which may create the environment).
    """

    spec = None

    def __init__(self, spec: HostSceneSpec, options: Any, env_name: str, python: str) -> None:
        self.host_spec = spec
        self.name, self.task, self.robot_name = spec.name, spec.task, spec.robot
        self.options = options
        self.env_name = env_name
        self.batch = EnvBatch(dataclasses.replace(spec.batch, python=python))
        self.backend = HostBackend(spec, self.batch, python, env_name)  # type: ignore[assignment]

    # ---- static layout ---------------------------------------------------------------------

    @property
    def max_steps(self) -> int:
        return self.host_spec.max_steps

    @property
    def action_size(self) -> int:
        return self.host_spec.batch.action_size

    @property
    def obs_layout(self) -> dict[str, tuple[int, int]]:
        """The flat observation's slices (`HostSceneSpec.flat_obs`); none for a dict."""
        if not self.host_spec.flat_obs:
            return {}
        return obs_slices({k: s[0] for k, (s, _) in self.host_spec.batch.observation.items()})

    @property
    def observation_size(self) -> int:
        """The flat vector's size; a ConfigError where the scene observes a dict of arrays."""
        if self.host_spec.flat_obs:
            return sum(size for _, size in self.obs_layout.values())
        raise ConfigError(
            f"scene {self.name!r} observes a dict of arrays "
            f"({', '.join(self.host_spec.batch.observation)}), not one flat vector: policies "
            "and trainers that need a flat vector (mlp, finetune) do not apply"
        )

    @property
    def instruction(self) -> str:
        """The spec's instruction, known without starting a worker."""
        return self.host_spec.instruction or super().instruction

    def action_bounds(self) -> tuple[jax.Array, jax.Array]:
        s = self.host_spec
        return jnp.asarray(s.action_low, jnp.float32), jnp.asarray(s.action_high, jnp.float32)

    def _shapes(self, lead: tuple[int, ...]) -> dict[str, Any]:
        sd = jax.ShapeDtypeStruct
        obs = {
            k: sd((*lead, *shape), jnp.dtype(dtype))
            for k, (shape, dtype) in self.host_spec.batch.observation.items()
        }
        out = {
            "obs": obs,
            "reward": sd(lead, jnp.float32),
            "terminated": sd(lead, jnp.bool_),
            "success": sd(lead, jnp.bool_),
            "diverged": sd(lead, jnp.bool_),
            "error": sd(lead, jnp.int32),
            "slot": sd(lead, jnp.int32),
        }
        factors = self.host_spec.batch.factors
        if factors:
            out["factors"] = sd((*lead, len(factors)), jnp.float32)
        return out

    # ---- host side -------------------------------------------------------------------------

    @host_callback
    def _host_reset(
        self, seed: np.ndarray, env_seed: np.ndarray, drawn: np.ndarray
    ) -> dict[str, Any]:
        lead = np.shape(seed)
        seed, env_seed = np.asarray(seed).reshape(-1), np.asarray(env_seed).reshape(-1)
        drawn = np.asarray(drawn, np.float64).reshape(len(seed), np.shape(drawn)[-1])
        spec = self.host_spec
        n_init = spec.n_init_states
        options = [
            {**spec.reset_options, **({"init_state": int(s) % n_init} if n_init else {})}
            for s in seed
        ]
        if spec.reset_draw is not None:
            for opts, vec in zip(options, drawn, strict=True):
                opts[spec.reset_draw_option] = vec.tolist()
        out = self.batch.reset(env_seed.astype(np.int64), options)
        out["slot"] = np.arange(len(seed), dtype=np.int32)
        return _reshape(out, lead)

    @host_callback
    def _host_step(self, slot: np.ndarray, action: np.ndarray, done: np.ndarray) -> dict:
        lead = np.shape(slot)  # the callback gets JAX arrays: to numpy before any indexing
        slot, action, done = np.asarray(slot).reshape(-1), np.asarray(action), np.asarray(done)
        if not np.array_equal(slot, np.arange(len(slot))):
            raise RuntimeError("host scene envs must be stepped in the order they were reset")
        action = np.reshape(action, (len(slot), -1))
        out = self.batch.step(action, np.reshape(done, -1))
        out["slot"] = slot.astype(np.int32)
        return _reshape(out, lead)

    # ---- JAX side --------------------------------------------------------------------------

    def _state(self, out: dict[str, Any], prev: State | None) -> State:
        error = out["error"]
        diverged = out["diverged"] & (error == 0)
        success = out["success"] & (error == 0) & ~diverged
        done = out["terminated"] | success | diverged | (error > 0)
        if prev is not None:  # finished envs stay finished with what they ended with
            error = jnp.where(prev.metrics["error"] > 0, prev.metrics["error"], error)
            success = success | prev.metrics["success"]
            diverged = diverged | prev.metrics["diverged"]
            done = done | prev.done
        obs = out["obs"]
        if self.host_spec.flat_obs:
            obs = jnp.concatenate([obs[k].astype(jnp.float32) for k in self.obs_layout], -1)
        return State(
            physics=None,
            obs=obs,
            reward=out["reward"],
            done=done,
            metrics={"success": success, "diverged": diverged, "error": error},
            info={"slot": out["slot"], **({"factors": out["factors"]} if "factors" in out else {})},
        )

    def reset(self, key: jax.Array) -> State:
        return self.reset_with_seed(jnp.zeros((), jnp.int32), key)

    def reset_with_seed(self, seed: jax.Array, key: jax.Array) -> State:
        env_seed = jax.random.randint(key, (), 0, 2**31 - 1, dtype=jnp.int32)
        draw = self.host_spec.reset_draw
        drawn = jnp.zeros((0,), jnp.float32) if draw is None else draw(key).astype(jnp.float32)
        out = jax.pure_callback(
            self._host_reset,
            self._shapes(()),
            seed.astype(jnp.int32),
            env_seed,
            drawn,
            vmap_method="broadcast_all",
        )
        return self._state(out, None)

    def step(self, state: State, action: jax.Array) -> State:
        low, high = self.action_bounds()
        out = jax.pure_callback(
            self._host_step,
            self._shapes(()),
            state.info["slot"],
            jnp.clip(action.astype(jnp.float32), low, high),
            state.done,
            vmap_method="broadcast_all",
        )
        return self._state(out, state)

    def episode_info(self, state: State) -> dict[str, jax.Array]:
        return {"error": state.metrics["error"]}

    def episode_factors(self, state: State) -> dict[str, jax.Array]:
        """The factors the env reported at reset (`HostSceneSpec.batch.factors`)."""
        names = self.host_spec.batch.factors
        return {name: state.info["factors"][i] for i, name in enumerate(names)}

    def describe_episode(self, info: Mapping[str, Any]) -> dict[str, Any]:
        code = int(info.get("error", 0))
        return {"error": self.batch.messages[code - 1] if code > 0 else None}

    def prepare(self, n_envs: int) -> None:
        """Start the workers and build the envs for `n_envs` slots before the run is timed; a
        simulator that cannot start is a `ConfigError` (nothing has run yet)."""
        try:
            self.batch.start(n_envs)
        except (WorkerFailure, RemoteError) as e:
            self.batch.messages.append(str(e))  # keeps the worker logs
            self.batch.close()
            raise ConfigError(
                f"scene {self.name!r}: its workers could not start: {e} (worker logs in "
                f"{self.batch.log_dir})"
            ) from None

    def on_ray(self, ray: ModuleType) -> None:
        """Run the workers as Ray actors on the connected cluster (see `EnvBatch.on_ray`)."""
        self.batch.on_ray(ray, self.env_name)

    def close(self) -> None:
        self.batch.close()


def _reshape(out: dict[str, Any], lead: tuple[int, ...]) -> dict[str, Any]:
    fix: Callable[[np.ndarray], np.ndarray] = lambda a: np.reshape(a, lead + np.shape(a)[1:])  # noqa: E731
    return jax.tree.map(fix, out)
