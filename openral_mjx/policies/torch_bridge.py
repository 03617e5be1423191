"""Torch inside the jitted episode: one `buffer_callback` per control step, on JAX's buffers.

A torch policy (`torch:`, or `lerobot:` where lerobot imports here) runs as a callback of the
fused episode, for the whole batch at once (`vmap_method="broadcast_all"`). It is a JAX
`buffer_callback`, not a `pure_callback`: the callback receives JAX's own device buffers,
which become torch tensors by DLPack without a copy, on the CPU as on a GPU, and the actions
are written in place into the output buffer JAX hands it. On a GPU the torch work is issued on
XLA's own stream (`torch.cuda.ExternalStream`), so it runs in order with the physics and no
array crosses to the host. (A `pure_callback` gets host copies on a GPU: device -> host ->
torch device for the observations, and back for the actions.)

Latency per step: on the CPU the callback's wall time; on a GPU, where the callback only issues
work, the GPU time between two CUDA events around the policy's kernels, read one step later
(reading it at once would wait for the GPU), so each step reports its predecessor's time.
"""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Callable, Mapping
from typing import Any

import jax
import jax.numpy as jnp
from jax.experimental.buffer_callback import buffer_callback

from openral_mjx.core.errors import ConfigError
from openral_mjx.host.pool import host_callback
from openral_mjx.policies.base import Policy, host_step_policy

# run(inputs, steps) -> actions: inputs by name, batch first, on the module's device; steps:
# each env's control step in its episode (0: the episode starts here), a 1-D int32 tensor.
RunFn = Callable[[dict[str, Any], Any], Any]


def import_torch() -> Any:
    """torch, or a ConfigError that says how to install it."""
    try:
        import torch
    except ImportError:
        raise ConfigError(
            "torch policies need PyTorch in this environment: pip install 'openral_mjx[torch]'"
        ) from None
    return torch


def choose_device(torch: Any) -> str:
    """`OPENRAL_MJX_TORCH_DEVICE`, else "cuda" where torch and JAX both run on a GPU, else
    "cpu"."""
    chosen = os.environ.get("OPENRAL_MJX_TORCH_DEVICE")
    if chosen:
        return chosen
    if torch.cuda.is_available() and jax.default_backend() == "gpu":
        return "cuda"
    return "cpu"


class _Latency:
    """Per-step policy time (see the module docstring): wall time on the CPU, CUDA events read
    one step late on a GPU."""

    def __init__(self, torch: Any) -> None:
        self.torch = torch
        self.begin: Any = None  # this step's start event on a GPU, None on the CPU
        self.pending: tuple[Any, Any] | None = None  # the previous step's (start, end) events
        self.start_s = 0.0

    def start(self, cuda: bool) -> None:
        self.begin = None
        if cuda:
            self.begin = self.torch.cuda.Event(enable_timing=True)
            self.begin.record()
        else:
            self.start_s = time.perf_counter()

    def stop_ms(self) -> float:
        if self.begin is None:
            return 1000 * (time.perf_counter() - self.start_s)
        end = self.torch.cuda.Event(enable_timing=True)
        end.record()
        done, self.pending = self.pending, (self.begin, end)
        if done is None:
            return 0.0
        done[1].synchronize()  # issued a step ago: the GPU has (nearly) finished it
        return float(done[0].elapsed_time(done[1]))


class TorchBridge:
    """The per-step `buffer_callback`: JAX buffers in, `run`'s actions written in place."""

    def __init__(
        self, torch: Any, run: RunFn, shapes: Mapping[str, tuple[int, ...]], action_size: int
    ) -> None:
        self.torch, self.run = torch, run
        self.shapes, self.action_size = dict(shapes), action_size
        self.latency = _Latency(torch)

    def _stream(self, ctx: Any, cuda: bool, device: Any) -> Any:
        if not cuda:
            return contextlib.nullcontext()
        return self.torch.cuda.stream(self.torch.cuda.ExternalStream(ctx.stream, device=device))

    @host_callback
    def __call__(self, ctx: Any, out: tuple[Any, Any], arrays: dict[str, Any], t: Any) -> None:
        torch = self.torch
        action_out, ms_out = (torch.from_dlpack(b) for b in out)
        steps = torch.from_dlpack(t).reshape(-1)
        n = steps.shape[0]
        cuda = steps.is_cuda
        with self._stream(ctx, cuda, steps.device), torch.inference_mode():
            self.latency.start(cuda)
            inputs = {
                k: torch.from_dlpack(v).reshape(n, *self.shapes[k]) for k, v in arrays.items()
            }
            action = self.run(inputs, steps)
            if not isinstance(action, torch.Tensor):
                action = torch.as_tensor(action)
            action_out.reshape(n, self.action_size).copy_(action.reshape(n, self.action_size))
            ms_out.fill_(self.latency.stop_ms())


def bridge_policy(
    name: str,
    bridge: TorchBridge,
    views: Callable[[Any], Mapping[str, jax.Array]],
    *,
    instruct: Callable[[str], None] | None = None,
    close: Callable[[], None] | None = None,
    aligned_episodes: bool = False,
) -> Policy:
    """A JAX `Policy` whose `act` is one `bridge` call for the batch; `views(obs)`: one env's
    observation as the named arrays `bridge` reads (pure JAX, traced into the episode)."""
    sd = jax.ShapeDtypeStruct
    call = buffer_callback(
        bridge,
        (sd((bridge.action_size,), jnp.float32), sd((), jnp.float32)),
        vmap_method="broadcast_all",
    )
    names = list(bridge.shapes)

    def named(obs: Any) -> dict[str, jax.Array]:
        arrays = views(obs)
        return {k: arrays[k] for k in names}

    return host_step_policy(
        name,
        call,
        named,
        instruct=instruct,
        close=close,
        aligned_episodes=aligned_episodes,
        one_device=True,  # one module, one latency clock: no concurrent device shards
    )


def dry_run(
    torch: Any,
    run: RunFn,
    shapes: Mapping[str, tuple[int, ...]],
    dtypes: Mapping[str, Any],
    device: str,
    n: int = 2,
) -> Any:
    """`run` on a batch of `n` zero observations, to check it before compiling; the actions
    as a CPU tensor. The envs are mid-episode (step 1), so nothing is reset."""
    inputs = {
        k: torch.zeros((n, *shape), dtype=getattr(torch, jnp.dtype(dtypes[k]).name), device=device)
        for k, shape in shapes.items()
    }
    with torch.inference_mode():
        action = run(inputs, torch.ones(n, dtype=torch.int32, device=device))
    if not isinstance(action, torch.Tensor):
        action = torch.as_tensor(action)
    return action.detach().to("cpu", torch.float32)
