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

Each control step is one `buffer_callback` for the whole batch (`policies.torch_bridge`):
the module reads JAX's own buffers through DLPack and its actions are written into JAX's
output buffer, with no copy and, on a GPU, no trip through the host (torch runs on XLA's
stream). The module runs under `torch.inference_mode`.

Device: `OPENRAL_MJX_TORCH_DEVICE` if set, else CUDA where torch sees a GPU and JAX runs on
one, else the CPU. Shapes are checked with a two-env dry run when the policy is built.
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import sys
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from openral_mjx.core.errors import ConfigError
from openral_mjx.policies.base import Policy
from openral_mjx.policies.torch_bridge import (
    TorchBridge,
    bridge_policy,
    choose_device,
    dry_run,
    import_torch,
)

FACTORY_KWARGS = ("observation_spec", "action_size", "device", "instruction", "task")
LANGUAGE_KWARGS = ("task", "instruction")  # the module's per-step language parameter


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


def language_kwarg(module: Any) -> str | None:
    """The parameter of `module`'s forward (or call) that takes the instruction, if it names
    one of `LANGUAGE_KWARGS`."""
    target = getattr(module, "forward", module)
    try:
        params = inspect.signature(target).parameters
    except (TypeError, ValueError):
        return None
    return next((k for k in LANGUAGE_KWARGS if k in params), None)


def _observation_spec(scene: Any) -> dict[str, Any]:
    spec = scene.observation_spec
    return dict(spec) if isinstance(spec, Mapping) else {"obs": spec}


class ModuleRun:
    """Calls the module on a step's batch: inputs moved to its device, the instruction passed
    where it takes one, `reset(envs)` first for the envs whose episode starts."""

    def __init__(self, torch: Any, module: Any, device: str, flat: bool, instruction: str) -> None:
        self.torch, self.module, self.device, self.flat = torch, module, device, flat
        reset = getattr(module, "reset", None)
        self.reset = reset if callable(reset) else None
        self.instruction = instruction
        self.language = language_kwarg(module)

    def instruct(self, text: str) -> None:
        """The instruction passed to the module from the next step on."""
        self.instruction = text

    def __call__(self, inputs: dict[str, Any], steps: Any) -> Any:
        n = steps.shape[0]
        inputs = {k: v.to(self.device) for k, v in inputs.items()}
        if self.reset is not None:
            starting = self.torch.nonzero(steps == 0).reshape(-1).to("cpu", self.torch.int64)
            if starting.numel():
                self.reset(starting)
        language = {self.language: [self.instruction] * n} if self.language else {}
        return self.module(inputs["obs"] if self.flat else inputs, **language)


def torch_policy(scene: Any, arg: str | None) -> Policy:
    """`torch:MODULE:FACTORY` for `scene`: builds the module, checks its output shape on a
    two-env batch of zeros, and wraps it as a JAX policy (see the module docstring)."""
    if not arg:
        raise ConfigError("policy 'torch' needs MODULE:FACTORY: --policy torch:MODULE:FACTORY")
    torch = import_torch()
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
    run = ModuleRun(torch, module, device, flat, scene.instruction)
    try:
        dry = dry_run(torch, run, shapes, {k: v.dtype for k, v in spec.items()}, device)
    except Exception as e:  # the user's module failing on a well-formed batch
        raise ConfigError(f"torch policy {arg}: failed on a batch of 2 observations: {e}") from e
    if dry.numel() != 2 * scene.action_size:
        raise ConfigError(
            f"torch policy {arg} returned {dry.numel() // 2} action values per env; scene "
            f"{scene.name!r} takes {scene.action_size}"
        )
    bridge = TorchBridge(torch, run, shapes, int(scene.action_size))
    views = (lambda obs: {"obs": obs}) if flat else (lambda obs: obs)
    return bridge_policy(f"torch:{arg}", bridge, views, instruct=run.instruct)
