"""`lerobot:PATH`: a lerobot policy directory as a JAX policy, through a host callback.

The policy runs batched in a server process of the ``lerobot-libero`` worker environment
(`openral_mjx.host.lerobot_server`; lerobot needs a torch the evaluator's environment cannot
hold). `act` is a `jax.pure_callback` that vmap hands the whole batch (`vmap_method=
"broadcast_all"`): one call per control step sends every env's observation to the server,
which runs lerobot's pre-processor, `select_action` (replaying the policy's action chunks) and
post-processor, and returns the actions. The callback's round trip is the step's policy
latency; the runner accumulates it per episode against the control period.

Observation keys. Each input feature of the policy (``config.json``) takes one observation
array of the scene, by this rule unless ``PATH/openral_mjx_keys.yaml`` maps ``feature:
scene_key`` explicitly: ``observation.images.NAME`` takes ``NAME`` (``image2`` also
``wrist_image``, lerobot's name for LIBERO's wrist camera); ``observation.image`` takes
``image`` or ``pixels`` and ``observation.state`` takes ``state`` or ``agent_pos`` (lerobot's
gym-env names, e.g. its MetaWorld env's); ``observation.environment_state`` takes
``environment_state`` or ``object``; in a scene whose observation is one flat vector, both
state features take that vector. Images are uint8 (H, W, C) in the scene and (C, H, W) in the
policy's features; shapes must agree.

Language. Every batch carries the scene's `instruction` under lerobot's ``task`` key (one
string per env), as lerobot's own evaluation hands every policy its env's task description:
VLA policies (SmolVLA, pi0) read it, the others ignore it. `Policy.instruct` changes it
between evaluations (a suite's tasks).
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import yaml

from openral_mjx.core.errors import ConfigError
from openral_mjx.host.envs import ensure_env
from openral_mjx.host.pool import RemoteError, Worker, WorkerFailure, host_callback
from openral_mjx.policies.base import Policy

ENV = "lerobot-libero"  # the worker environment that holds lerobot and its torch
KEYS_FILE = "openral_mjx_keys.yaml"
ALIASES = {"image2": ("image2", "wrist_image")}
INIT_TIMEOUT_S = 900.0
STEP_TIMEOUT_S = 300.0


def read_features(path: Path) -> tuple[dict[str, tuple[str, tuple[int, ...]]], int]:
    """The policy's input features (name -> (type, shape)) and action size, from config.json."""
    config_file = path / "config.json"
    if not config_file.is_file():
        raise ConfigError(f"lerobot policy {str(path)!r}: no config.json (a saved policy dir?)")
    try:
        config = json.loads(config_file.read_text())
        inputs = {k: (v["type"], tuple(v["shape"])) for k, v in config["input_features"].items()}
        action = tuple(config["output_features"]["action"]["shape"])
    except (ValueError, KeyError, TypeError) as e:
        raise ConfigError(f"lerobot policy {str(path)!r}: unreadable config.json ({e})") from None
    return inputs, int(np.prod(action))


def _scene_arrays(spec: Any) -> dict[str, jax.ShapeDtypeStruct]:
    """The scene's observation as named arrays (a flat vector is named `obs`)."""
    if isinstance(spec, Mapping):
        return dict(spec)
    return {"obs": spec}


def key_map(
    features: Mapping[str, tuple[str, tuple[int, ...]]],
    observation: Mapping[str, jax.ShapeDtypeStruct],
    explicit: Mapping[str, str] | None = None,
) -> dict[str, str]:
    """feature -> scene observation key, checked for presence and shape (see module doc)."""
    explicit = dict(explicit or {})
    unknown = sorted(set(explicit) - set(features))
    if unknown:
        raise ConfigError(
            f"{KEYS_FILE}: {unknown} are not inputs of the policy ({sorted(features)})"
        )
    out = {}
    for name, (kind, shape) in features.items():
        if name in explicit:
            candidates: tuple[str, ...] = (explicit[name],)
        elif name.startswith("observation.images."):
            short = name.removeprefix("observation.images.")
            candidates = ALIASES.get(short, (short,))
        elif name == "observation.image":
            candidates = ("image", "pixels")
        elif name == "observation.state":
            candidates = ("state", "agent_pos", "obs")
        elif name == "observation.environment_state":
            candidates = ("environment_state", "object", "obs")
        else:
            candidates = (name,)
        key = next((c for c in candidates if c in observation), None)
        if key is None:
            raise ConfigError(
                f"policy input {name!r} has no observation: tried {list(candidates)}, the scene "
                f"has {sorted(observation)}; map it in {KEYS_FILE}"
            )
        have = tuple(observation[key].shape)
        want = (shape[1], shape[2], shape[0]) if kind == "VISUAL" and len(shape) == 3 else shape
        if have != want:
            raise ConfigError(
                f"policy input {name!r} {kind} shape {list(shape)} does not fit observation "
                f"{key!r} of shape {list(have)}"
            )
        out[name] = key
    return out


class LerobotClient:
    """The evaluator's side of one policy server; `__call__` is the per-step host callback."""

    def __init__(
        self, path: Path, keys: dict[str, str], action_size: int, instruction: str = ""
    ) -> None:
        self.path, self.keys, self.action_size = path, keys, action_size
        self.instruction = instruction
        self.worker: Worker | None = None

    def instruct(self, text: str) -> None:
        """The instruction sent with every following step (see the module docstring)."""
        self.instruction = text

    def start(self) -> None:
        if self.worker is not None and self.worker.alive:
            return
        python = ensure_env(ENV)
        log = Path(os.environ.get("TMPDIR", "/tmp")) / f"openral_mjx_lerobot_{os.getpid()}.log"
        self.worker = Worker(python, {"HF_HUB_OFFLINE": "1"}, log, name="lerobot policy server")
        device = os.environ.get("OPENRAL_MJX_LEROBOT_DEVICE") or None
        try:
            self.worker.call(
                {
                    "op": "init",
                    "factory": "openral_mjx.host.lerobot_server:LerobotServer",
                    "kwargs": {"path": str(self.path), "device": device},
                },
                INIT_TIMEOUT_S,
            )
        except (WorkerFailure, RemoteError) as e:
            self.close()
            raise ConfigError(f"lerobot policy {str(self.path)!r} failed to load: {e}") from None

    @host_callback
    def __call__(self, obs: dict[str, Any], t: Any) -> tuple[np.ndarray, np.ndarray]:
        lead = np.shape(t)
        t = np.asarray(t).reshape(-1)
        n = len(t)
        inputs = {
            f: np.asarray(obs[k]).reshape(n, *np.shape(obs[k])[len(lead) :])
            for f, k in self.keys.items()
        }
        self.start()
        assert self.worker is not None
        start = time.perf_counter()
        reply = self.worker.call(
            {
                "op": "call",
                "method": "act",
                "kwargs": {
                    "obs": inputs,
                    "reset": bool((t == 0).all()),
                    "task": self.instruction,
                },
            },
            STEP_TIMEOUT_S,
        )
        ms = 1000 * (time.perf_counter() - start)
        action = np.asarray(reply["action"], np.float32).reshape(*lead, self.action_size)
        return action, np.full(lead, ms, np.float32)

    def close(self) -> None:
        if self.worker is not None:
            self.worker.close()
            self.worker = None


def lerobot_policy(scene: Any, arg: str | None) -> Policy:
    """`lerobot:PATH` for `scene`: checks the policy's features against the scene's
    observation and action, starts the policy server, and wraps it as a JAX policy."""
    if not arg:
        raise ConfigError("policy 'lerobot' needs a directory: --policy lerobot:PATH")
    path = Path(arg).expanduser().resolve()
    if not path.is_dir():
        raise ConfigError(f"lerobot policy directory {arg!r} does not exist")
    features, action_size = read_features(path)
    if action_size != scene.action_size:
        raise ConfigError(
            f"lerobot policy {arg!r} outputs {action_size} action values; scene "
            f"{scene.name!r} takes {scene.action_size}"
        )
    explicit = None
    if (path / KEYS_FILE).is_file():
        explicit = yaml.safe_load((path / KEYS_FILE).read_text()) or {}
        if not isinstance(explicit, dict):
            raise ConfigError(f"{path / KEYS_FILE}: expected a mapping feature: scene_key")
    observation = _scene_arrays(scene.observation_spec)
    keys = key_map(features, observation, explicit)
    client = LerobotClient(path, keys, action_size, scene.instruction)
    client.start()
    flat = not isinstance(scene.observation_spec, Mapping)
    sd = jax.ShapeDtypeStruct

    def init(key, obs_spec):
        del key, obs_spec
        return None, {"t": jnp.zeros((), jnp.int32), "ms": jnp.zeros((), jnp.float32)}

    def act(params, pstate, obs, key):
        del params, key
        arrays = {"obs": obs} if flat else obs
        needed = {k: arrays[k] for k in set(keys.values())}
        action, ms = jax.pure_callback(
            client,
            (sd((action_size,), jnp.float32), sd((), jnp.float32)),
            needed,
            pstate["t"],
            vmap_method="broadcast_all",
        )
        return action, {"t": pstate["t"] + 1, "ms": ms}

    return Policy(
        f"lerobot:{arg}",
        init,
        act,
        latency_ms=lambda s: s["ms"],
        close=client.close,
        instruct=client.instruct,
    )
