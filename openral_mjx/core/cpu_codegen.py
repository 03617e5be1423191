"""XLA's CPU code generation pinned so a seed's episode does not depend on its batch lane.

XLA's CPU backend lets LLVM contract ``a * b + c`` into fused multiply-adds (one rounding
instead of two), and it does so in some vector lanes of a batched loop and not in others
(openxla/xla#41579 shows the contraction). A seed's task logic then rounds differently by
where the seed sits in the batch: on `libero_mjx`'s `c` backend, seed 3 of `libero_object/0`
alone and first in the batch [3, 7] differed by 4.8e-7 after 12 control steps, growing
through contacts. Capping the instruction set at AVX (no FMA instructions) makes every lane
compute alike: every layout tried then gives the same bits.

The cap must be in ``XLA_FLAGS`` before JAX starts its CPU backend (a per-compile option is
ignored), so the package sets it when imported, on x86-64 only (the flag names x86 ISAs). A
user's own ``--xla_cpu_max_isa`` wins, and ``OPENRAL_MJX_CPU_ISA=native`` keeps XLA's default
(FMA on: faster JAX-side arithmetic, but a seed's last bits may depend on its batch lane).
"""

from __future__ import annotations

import os
import platform

FLAG = "--xla_cpu_max_isa"
PINNED_ISA = "AVX"
OPT_OUT = "OPENRAL_MJX_CPU_ISA"


def pin_cpu_isa(environ: dict[str, str] | None = None, machine: str | None = None) -> bool:
    """Add ``--xla_cpu_max_isa=AVX`` to ``XLA_FLAGS`` in `environ` (default: this process's)
    unless the user chose an ISA or opted out, or the machine is not x86-64. Returns whether
    XLA's CPU code is pinned (by this call or by the user's own flag)."""
    env = os.environ if environ is None else environ
    flags = env.get("XLA_FLAGS", "")
    if FLAG in flags:
        return True
    if env.get(OPT_OUT, "").lower() == "native":
        return False
    if (machine or platform.machine()).lower() not in ("x86_64", "amd64"):
        return False
    env["XLA_FLAGS"] = f"{flags} {FLAG}={PINNED_ISA}".strip()
    return True
