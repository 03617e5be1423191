"""`lerobot:PATH`: a lerobot policy directory as a JAX policy, one batched call per step.

Where lerobot imports in the evaluator's own environment (Python 3.12 with lerobot 0.6 and
CUDA torch beside jax: the `lerobot` extra), the policy runs in process
(`host.lerobot_server.LerobotRunner` behind `policies.torch_bridge`): the observations are
JAX's own buffers, read by torch through DLPack with no copy (on a GPU, on XLA's stream), and
the actions are written back into JAX's output buffer. Elsewhere (lerobot 0.4 pins a torch the
evaluator's Python 3.11 environment cannot hold) it runs in a server process of the
``lerobot-libero`` worker environment: `act` is a `jax.pure_callback` that vmap hands the whole
batch (`vmap_method="broadcast_all"`), and each control step sends every env's observation
over the worker's pipe. `OPENRAL_MJX_LEROBOT=server` (or `process`) forces one path. Both run
the same `LerobotRunner`: lerobot's pre-processor, the policy with its action chunks replayed
per env (an env starting an episode gets a fresh chunk, so continuous batching gives each seed
its own episode), and the post-processor. The call's time is the step's policy latency; the
runner accumulates it per episode against the control period.

Observation keys. Each input feature of the policy (``config.json``) takes one observation
array of the scene, by this rule unless ``PATH/openral_mjx_keys.yaml`` maps ``feature:
scene_key`` explicitly: ``observation.images.NAME`` takes ``NAME`` or ``rgb_NAME`` (our
scenes' rendered cameras; ``image2`` also ``wrist_image``, lerobot's name for LIBERO's wrist
camera); ``observation.image`` takes
``image`` or ``pixels`` and ``observation.state`` takes ``state`` or ``agent_pos`` (lerobot's
gym-env names, e.g. its MetaWorld env's); ``observation.environment_state`` takes
``environment_state`` or ``object``; in a scene whose observation is one flat vector, both
state features take that vector, less its sensor slices (`scene_arrays`: each rendered camera
is its own ``rgb_CAMERA`` image). Images are (H, W, C) in the scene (uint8 from host scenes
and LIBERO's mirror, float in [0, 1] from our other scenes) and (C, H, W) in the policy's
features; shapes must agree.
Where `--opt` sets no cameras, the policy's image features choose them
(`implied_camera_options`): `obs_rgb_cameras`/`obs_rgb_size` on our scenes, `image_size` on
LIBERO's and the other host scenes that render square cameras.

Language. Every batch carries the scene's `instruction` under lerobot's ``task`` key (one
string per env), as lerobot's own evaluation hands every policy its env's task description:
VLA policies (SmolVLA, pi0) read it, the others ignore it. `Policy.instruct` changes it
between evaluations (a suite's tasks).
"""

from __future__ import annotations

import dataclasses
import importlib.util
import json
import os
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import yaml

from openral_mjx.core.errors import ConfigError
from openral_mjx.host.envs import ensure_env
from openral_mjx.host.pool import RemoteError, Worker, WorkerFailure, host_callback
from openral_mjx.policies.base import Policy, host_step_policy, pure_step_call
from openral_mjx.policies.torch_bridge import (
    TorchBridge,
    bridge_policy,
    choose_device,
    import_torch,
)

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


def policy_images(path: Path) -> dict[str, tuple[int, ...]]:
    """The policy's image features (``observation.images.NAME`` and PushT's
    ``observation.image``), name -> (C, H, W), from its config.json."""
    features, _ = read_features(path)
    return {
        name: shape
        for name, (kind, shape) in features.items()
        if kind == "VISUAL"
        and (name == "observation.image" or name.startswith("observation.images."))
        and len(shape) == 3
    }


def square_size(images: Mapping[str, tuple[int, ...]]) -> int | None:
    """The one side of `images` where all are RGB, square and the same size; else None."""
    sizes = {(shape[0], shape[1], shape[2]) for shape in images.values()}
    if len(sizes) != 1:
        return None
    ((channels, height, width),) = sizes
    return height if channels == 3 and height == width else None


def implied_camera_options(
    policy: str, options_cls: type, options: Mapping[str, Any] | None
) -> dict[str, Any]:
    """Scene options a `lerobot:PATH` policy's image features imply, so that its cameras need
    no `--opt`, unless `options` set them or the policy maps its keys by hand (`KEYS_FILE`):

    - `obs_rgb_cameras` (the NAMEs of its ``observation.images.NAME`` features) and
      `obs_rgb_size` ((W, H) of them), where the scene renders named RGB cameras (its options
      have both) and the features share one size;
    - `image_size` (their side), where the scene renders its own cameras square at one size
      (LIBERO, its mirror, robosuite, PushT, MetaWorld: options with `image_size`) and the
      features are all square RGB of one size.

    Empty otherwise; a camera the scene cannot serve is then `lerobot_policy`'s error."""
    if not policy.startswith("lerobot:") or not dataclasses.is_dataclass(options_cls):
        return {}
    names = {f.name for f in dataclasses.fields(options_cls)}
    given = set(options or {})
    path = Path(policy.removeprefix("lerobot:")).expanduser()
    if not (path / "config.json").is_file() or (path / KEYS_FILE).is_file():
        return {}
    rgb = {"obs_rgb_cameras", "obs_rgb_size"}
    if rgb <= names and not given & rgb:
        images = {
            k.removeprefix("observation.images."): s
            for k, s in policy_images(path).items()
            if k.startswith("observation.images.")
        }
        sizes = {(shape[2], shape[1]) for shape in images.values()}
        if not images or len(sizes) != 1 or any(shape[0] != 3 for shape in images.values()):
            return {}
        (size,) = sizes
        return {"obs_rgb_cameras": sorted(images), "obs_rgb_size": list(size)}
    if "image_size" in names and "image_size" not in given:
        side = square_size(policy_images(path))
        return {} if side is None else {"image_size": side}
    return {}


def check_cameras(scene: Any, arg: str, path: Path, observation: Mapping[str, Any]) -> None:
    """A one-line ConfigError where the policy reads images and the scene, one that renders
    square cameras by option `image_size` (LIBERO's mirror), draws none or the wrong size."""
    options = getattr(scene, "options", None)
    if not hasattr(options, "image_size") or (path / KEYS_FILE).is_file():
        return
    images = policy_images(path)
    if not images:
        return
    shapes = sorted({tuple(s) for s in images.values()})
    side = square_size(images)
    fix = f"--opt image_size={side}" if side else "a policy whose images are square, one size"
    if not any(len(v.shape) == 3 for v in observation.values()):
        raise ConfigError(
            f"lerobot policy {arg!r} reads images {sorted(images)} of (C, H, W) {shapes}; "
            f"scene {scene.name!r} renders none without option image_size: {fix}"
        )
    size = options.image_size
    if side != size:
        raise ConfigError(
            f"lerobot policy {arg!r} reads images {sorted(images)} of (C, H, W) {shapes}; "
            f"scene {scene.name!r} renders square RGB of option image_size={size}: {fix}"
        )


def scene_arrays(scene: Any) -> dict[str, jax.ShapeDtypeStruct]:
    """The scene's observation as named arrays. A flat vector is `obs`; where it carries
    sensor slices (images, a laser: `Scene.sensor_shapes`), `obs` is the rest (joints, task
    values) and each sensor is its own array, `rgb_CAMERA` (H, W, 3) in [0, 1] and so on."""
    spec = scene.observation_spec
    if isinstance(spec, Mapping):
        return dict(spec)
    sensors = dict(getattr(scene, "sensor_shapes", None) or {})
    if not sensors:
        return {"obs": spec}
    sd = jax.ShapeDtypeStruct
    state = sum(size for k, (_, size) in scene.obs_layout.items() if k not in sensors)
    return {"obs": sd((state,), spec.dtype)} | {k: sd(v, spec.dtype) for k, v in sensors.items()}


def split_flat(scene: Any, obs: jax.Array) -> dict[str, jax.Array]:
    """One env's flat observation as `scene_arrays` names them (pure JAX, in the episode)."""
    sensors = dict(getattr(scene, "sensor_shapes", None) or {})
    if not sensors:
        return {"obs": obs}
    layout = scene.obs_layout
    rest = [obs[a : a + n] for k, (a, n) in layout.items() if k not in sensors]
    out = {"obs": jnp.concatenate(rest)}
    for k, shape in sensors.items():
        a, n = layout[k]
        out[k] = obs[a : a + n].reshape(shape)
    return out


def observation_views(scene: Any) -> Callable[[Any], dict[str, jax.Array]]:
    """One env's observation -> `scene_arrays`' named arrays (pure JAX, in the episode)."""
    if isinstance(scene.observation_spec, Mapping):
        return dict
    return lambda obs: split_flat(scene, obs)


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
            candidates = (*ALIASES.get(short, (short,)), f"rgb_{short}")
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
        self.described: dict[str, Any] = {}

    def instruct(self, text: str) -> None:
        """The instruction sent with every following step (see the module docstring)."""
        self.instruction = text

    def start(self) -> dict[str, Any]:
        """Starts the server if it is not running; what it says of the policy (`describe`)."""
        if self.worker is not None and self.worker.alive:
            return self.described
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
            self.described = self.worker.call(
                {"op": "call", "method": "describe", "kwargs": {}}, INIT_TIMEOUT_S
            )
        except (WorkerFailure, RemoteError) as e:
            self.close()
            raise ConfigError(f"lerobot policy {str(self.path)!r} failed to load: {e}") from None
        return self.described

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
                "kwargs": {"obs": inputs, "steps": t.tolist(), "task": self.instruction},
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
    observation = scene_arrays(scene)
    check_cameras(scene, arg, path, observation)
    keys = key_map(features, observation, explicit)
    if in_process():
        return _in_process(scene, arg, path, keys, action_size)
    client = LerobotClient(path, keys, action_size, scene.instruction)
    described = client.start()
    views = observation_views(scene)
    needed = sorted(set(keys.values()))

    def named(obs: Any) -> dict[str, jax.Array]:
        arrays = views(obs)
        return {k: arrays[k] for k in needed}

    return host_step_policy(
        f"lerobot:{arg}",
        pure_step_call(client, action_size),
        named,
        close=client.close,
        instruct=client.instruct,
        aligned_episodes=not described.get("per_env", False),
        one_device=True,  # one server, one pipe: no concurrent device shards
    )


def in_process() -> bool:
    """Whether `lerobot:` runs in this process: `OPENRAL_MJX_LEROBOT` (`process` / `server`)
    if set, else where lerobot is installed here."""
    chosen = os.environ.get("OPENRAL_MJX_LEROBOT", "").strip().lower()
    if chosen not in ("", "process", "server"):
        raise ConfigError(
            f"OPENRAL_MJX_LEROBOT={chosen!r} is not a lerobot path; valid: process, server"
        )
    if chosen:
        return chosen == "process"
    return importlib.util.find_spec("lerobot") is not None


class _FeatureRun:
    """The bridge's step function: scene observations renamed to the policy's features."""

    def __init__(self, runner: Any, keys: dict[str, str], instruction: str) -> None:
        self.runner, self.keys, self.instruction = runner, keys, instruction

    def instruct(self, text: str) -> None:
        self.instruction = text

    def __call__(self, inputs: dict[str, Any], steps: Any) -> Any:
        obs = {feature: inputs[key] for feature, key in self.keys.items()}
        return self.runner(obs, steps, self.instruction)


def _in_process(scene: Any, arg: str, path: Path, keys: dict[str, str], action_size: int) -> Policy:
    """`lerobot:PATH` run by `LerobotRunner` in this process, through the torch bridge."""
    torch = import_torch()
    try:
        from openral_mjx.host.lerobot_server import LerobotRunner

        runner = LerobotRunner(str(path), choose_device(torch))
    except ImportError as e:
        raise ConfigError(
            f"lerobot policy {arg!r}: lerobot does not import here ({e}); set "
            "OPENRAL_MJX_LEROBOT=server to run it in the lerobot worker environment"
        ) from None
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise ConfigError(f"lerobot policy {arg!r} failed to load: {e}") from None
    observation = scene_arrays(scene)
    needed = sorted(set(keys.values()))
    shapes = {k: tuple(observation[k].shape) for k in needed}
    run = _FeatureRun(runner, keys, scene.instruction)
    bridge = TorchBridge(torch, run, shapes, action_size)
    return bridge_policy(
        f"lerobot:{arg}",
        bridge,
        observation_views(scene),
        instruct=run.instruct,
        aligned_episodes=not runner.per_env,
    )
