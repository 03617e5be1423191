"""`torch:MODULE:FACTORY`: any torch module in the evaluator's own process, as a JAX policy.

`MODULE:FACTORY` names a callable (`my_pkg.policies:make`, or a file, `path/to/file.py:make`)
that builds an `nn.Module`-like callable from the batch of observations to a `(batch,
action_size)` tensor of actions: one `(batch, n)` tensor where the scene observes one flat
vector (`tabletop_push`, `so101_box`: a plain `nn.Sequential` MLP fits), else a dict of tensors
by observation name (batch first; host scenes' images are uint8 `(batch, H, W, C)`). The
factory gets, by keyword, whichever of `observation_spec` (name -> (shape, dtype) of one env's
observation; a flat one is named `obs`), `action_size`, `device` (the torch device it will
run on) and `instruction` or `task` (the scene's natural-language instruction) its signature
names.
A module whose `forward` (or call) names a `task` or `instruction` parameter gets the
instruction there at every step, one string per env (lerobot's `batch["task"]` convention;
`Policy.instruct` changes it between evaluations, e.g. a suite's tasks).
A module with a `reset(envs)` method is told which envs (a 1-D int64 tensor of batch rows)
start an episode before each step they do, for policies that keep per-env state (action
chunks).

Each control step is one `jax.pure_callback` for the whole batch (`vmap_method=
"broadcast_all"`), as for `lerobot:`, but without a process in between: the callback's arrays
become torch tensors by DLPack (no copy on the CPU: the module reads JAX's buffers), move to
the module's device (a copy where torch runs on a GPU: JAX hands host callbacks host arrays),
and the actions come back as float32 without a copy on the CPU. The module runs under
`torch.inference_mode`. The callback's duration is the step's policy latency.

Device: `OPENRAL_MJX_TORCH_DEVICE` if set, else CUDA where torch sees a GPU and JAX runs on
one, else the CPU. Shapes are checked with a two-env dry run when the policy is built.
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import os
import sys
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from openral_mjx.core.errors import ConfigError
from openral_mjx.host.pool import host_callback
from openral_mjx.policies.base import Policy

FACTORY_KWARGS = ("observation_spec", "action_size", "device", "instruction", "task")
LANGUAGE_KWARGS = ("task", "instruction")  # the module's per-step language parameter


def _import_torch() -> Any:
    try:
        import torch
    except ImportError:
        raise ConfigError(
            "policy 'torch' needs PyTorch in this environment: pip install 'openral_mjx[torch]'"
        ) from None
    return torch


def load_factory(spec: str) -> Callable[..., Any]:
    """The callable `MODULE:FACTORY` names (MODULE a dotted module or a `.py` file)."""
    module_name, sep, attr = spec.rpartition(":")
    if not sep or not module_name or not attr:
        raise ConfigError(
            f"policy 'torch' needs MODULE:FACTORY (e.g. torch:my_pkg.policies:make or "
            f"torch:path/to/file.py:make), got torch:{spec}"
        )
    if module_name.endswith(".py"):
        path = Path(module_name).expanduser().resolve()
        if not path.is_file():
            raise ConfigError(f"torch policy file {module_name!r} does not exist")
        loader = importlib.util.spec_from_file_location(f"openral_mjx_torch_{path.stem}", path)
        assert loader is not None and loader.loader is not None
        module = importlib.util.module_from_spec(loader)
        sys.modules[loader.name] = module
        loader.loader.exec_module(module)
    else:
        try:
            module = importlib.import_module(module_name)
        except ImportError as e:
            raise ConfigError(f"torch policy module {module_name!r} does not import: {e}") from None
    factory = getattr(module, attr, None)
    if not callable(factory):
        valid = sorted(
            name
            for name, value in vars(module).items()
            if callable(value) and not name.startswith("_") and not inspect.ismodule(value)
        )
        raise ConfigError(
            f"torch policy {module_name}:{attr}: no callable {attr!r} in {module_name}; "
            f"valid: {', '.join(valid) or '(none)'}"
        )
    return factory


def choose_device(torch: Any) -> str:
    """`OPENRAL_MJX_TORCH_DEVICE`, else "cuda" where torch and JAX both run on a GPU, else
    "cpu"."""
    chosen = os.environ.get("OPENRAL_MJX_TORCH_DEVICE")
    if chosen:
        return chosen
    if torch.cuda.is_available() and jax.default_backend() == "gpu":
        return "cuda"
    return "cpu"


def to_torch(torch: Any, x: Any) -> Any:
    """An array from a host callback as a torch tensor, sharing its buffer where DLPack can
    (a JAX CPU array, a writable numpy array), else a copy."""
    try:
        return torch.from_dlpack(x)
    except (BufferError, TypeError, RuntimeError):
        return torch.as_tensor(np.array(x))


def language_kwarg(module: Any) -> str | None:
    """The parameter of `module`'s forward (or call) that takes the instruction, if it names
    one of `LANGUAGE_KWARGS`."""
    target = getattr(module, "forward", module)
    try:
        params = inspect.signature(target).parameters
    except (TypeError, ValueError):
        return None
    return next((k for k in LANGUAGE_KWARGS if k in params), None)


def _observation_spec(scene: Any) -> dict[str, jax.ShapeDtypeStruct]:
    spec = scene.observation_spec
    return dict(spec) if isinstance(spec, Mapping) else {"obs": spec}


class TorchStep:
    """The per-step host callback: observations in, actions and latency out."""

    def __init__(
        self,
        torch: Any,
        module: Any,
        device: str,
        shapes: Mapping[str, tuple[int, ...]],
        action_size: int,
        flat: bool,
        instruction: str = "",
    ) -> None:
        self.torch, self.module, self.device = torch, module, device
        self.shapes, self.action_size, self.flat = dict(shapes), action_size, flat
        reset = getattr(module, "reset", None)
        self.reset = reset if callable(reset) else None
        self.instruction = instruction
        self.language = language_kwarg(module)

    def instruct(self, text: str) -> None:
        """The instruction passed to the module from the next step on."""
        self.instruction = text

    def actions(self, obs: Mapping[str, Any], n: int, starting: np.ndarray | None) -> Any:
        """The module's actions for a batch of `n` envs, a float32 (n, action_size) tensor on
        the CPU; `starting`: rows that begin an episode (reset first)."""
        torch = self.torch
        with torch.inference_mode():
            inputs = {
                k: to_torch(torch, v).reshape(n, *self.shapes[k]).to(self.device)
                for k, v in obs.items()
            }
            if self.reset is not None and starting is not None and starting.size:
                self.reset(torch.as_tensor(starting, dtype=torch.int64))
            language = {self.language: [self.instruction] * n} if self.language else {}
            action = self.module(inputs["obs"] if self.flat else inputs, **language)
            if not isinstance(action, torch.Tensor):
                action = torch.as_tensor(action)
            return action.detach().to("cpu", torch.float32).reshape(n, -1).contiguous()

    @host_callback
    def __call__(self, obs: dict[str, Any], t: Any) -> tuple[np.ndarray, np.ndarray]:
        lead = np.shape(t)
        steps = np.asarray(t).reshape(-1)
        start = time.perf_counter()
        action = self.actions(obs, len(steps), np.flatnonzero(steps == 0))
        ms = 1000 * (time.perf_counter() - start)
        out = action.numpy().reshape(*lead, self.action_size)
        return out, np.full(lead, ms, np.float32)


def torch_policy(scene: Any, arg: str | None) -> Policy:
    """`torch:MODULE:FACTORY` for `scene`: builds the module, checks its output shape on a
    two-env batch of zeros, and wraps it as a JAX policy (see the module docstring)."""
    if not arg:
        raise ConfigError("policy 'torch' needs MODULE:FACTORY: --policy torch:MODULE:FACTORY")
    torch = _import_torch()
    factory = load_factory(arg)
    spec = _observation_spec(scene)
    device = choose_device(torch)
    offered = {
        "observation_spec": {k: (tuple(v.shape), np.dtype(v.dtype).name) for k, v in spec.items()},
        "action_size": int(scene.action_size),
        "device": device,
        "instruction": scene.instruction,
        "task": scene.instruction,
    }
    try:
        accepted = inspect.signature(factory).parameters
    except (TypeError, ValueError):
        accepted = {}
    takes_all = any(p.kind == p.VAR_KEYWORD for p in accepted.values())
    kwargs = {k: v for k, v in offered.items() if takes_all or k in accepted}
    module = factory(**kwargs)
    if hasattr(module, "to"):
        module = module.to(device)
    if hasattr(module, "eval"):
        module.eval()
    flat = not isinstance(scene.observation_spec, Mapping)
    shapes = {k: tuple(v.shape) for k, v in spec.items()}
    step = TorchStep(torch, module, device, shapes, int(scene.action_size), flat, scene.instruction)
    zeros = {k: np.zeros((2, *v.shape), v.dtype) for k, v in spec.items()}
    try:
        dry = step.actions(zeros, 2, None)
    except Exception as e:  # the user's module failing on a well-formed batch
        raise ConfigError(f"torch policy {arg}: failed on a batch of 2 observations: {e}") from e
    if dry.numel() != 2 * scene.action_size:
        raise ConfigError(
            f"torch policy {arg} returned {dry.numel() // 2} action values per env; scene "
            f"{scene.name!r} takes {scene.action_size}"
        )
    names = list(spec)
    sd = jax.ShapeDtypeStruct

    def init(key, obs_spec):
        del key, obs_spec
        return None, {"t": jnp.zeros((), jnp.int32), "ms": jnp.zeros((), jnp.float32)}

    def act(params, pstate, obs, key):
        del params, key
        arrays = {"obs": obs} if flat else {k: obs[k] for k in names}
        action, ms = jax.pure_callback(
            step,
            (sd((scene.action_size,), jnp.float32), sd((), jnp.float32)),
            arrays,
            pstate["t"],
            vmap_method="broadcast_all",
        )
        return action, {"t": pstate["t"] + 1, "ms": ms}

    return Policy(f"torch:{arg}", init, act, latency_ms=lambda s: s["ms"], instruct=step.instruct)
