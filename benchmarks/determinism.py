"""How reproducible is a backend on this machine? Same seeds: twice at one batch size, then
inside a larger batch.

    python benchmarks/determinism.py --backend warp --small 1024 --large 4096

Prints and writes (--out) the fraction of seeds whose episode (success, steps, first success
step, total reward bits) is identical between runs, and each run's success rate.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import tyro

from openral_mjx.core.files import write_json_atomic
from openral_mjx.physics import PhysicsSettings, resolve_backend_name
from openral_mjx.policies import make_policy
from openral_mjx.runner import run_seeds
from openral_mjx.runner.compile_cache import enable_compilation_cache
from openral_mjx.scenes import make_scene

FIELDS = ("success", "steps", "first_success_step", "total_reward", "diverged")


@dataclasses.dataclass
class Args:
    scene: str = "tabletop_push"
    backend: str = "auto"
    small: int = 1024
    large: int = 4096
    max_steps: int = 200
    out: Path = Path("results/determinism.json")


def same(a: dict, b: dict, n: int) -> dict[str, float]:
    """Fraction of the first `n` seeds identical per field, and for all fields at once."""
    eq = {k: np.asarray(a[k][:n]) == np.asarray(b[k][:n]) for k in FIELDS}
    out = {k: float(v.mean()) for k, v in eq.items()}
    out["episode"] = float(np.logical_and.reduce([eq[k] for k in FIELDS]).mean())
    return out


def main(args: Args) -> None:
    enable_compilation_cache()
    backend = resolve_backend_name(args.backend)
    settings = PhysicsSettings(batch_size=args.large)
    scene = make_scene(args.scene, backend=backend, settings=settings)
    policy = make_policy("scripted", scene)
    kw = dict(max_steps=args.max_steps)
    first, _ = run_seeds(scene, policy, None, seeds=np.arange(args.small), n_envs=args.small, **kw)
    again, _ = run_seeds(scene, policy, None, seeds=np.arange(args.small), n_envs=args.small, **kw)
    large, _ = run_seeds(scene, policy, None, seeds=np.arange(args.large), n_envs=args.large, **kw)
    result = {
        "scene": args.scene,
        "backend": backend,
        "small": args.small,
        "large": args.large,
        "rerun_identical": same(first, again, args.small),
        "in_larger_batch_identical": same(first, large, args.small),
        "success_rate": {
            "first": float(first["success"].mean()),
            "again": float(again["success"].mean()),
            "large_first_small": float(large["success"][: args.small].mean()),
            "large_all": float(large["success"].mean()),
        },
    }
    write_json_atomic(args.out, result)
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main(tyro.cli(Args))
