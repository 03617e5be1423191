"""Which MuJoCo options keep the LIBERO mirror's episodes finite on `warp` (issue 37).

`libero_10/0`'s expert on `warp` (512 contacts per env, one H200, 2026-12-02) had 22 of 200
episodes go non-finite, none from a full buffer, each at control step 250-262: the steps at
which the others succeed (246-266), as the second can drops into the basket. On `c` none
diverged, and warp's CPU mode played seed 10 (diverged on the GPU at step 254) to success at
step 255. So the suspect is float32 convex collision (GJK/EPA between the cans' and the
basket's meshes) or the float32 Newton solver at that contact.

Per configuration, in one process: the task's model with some of its `mjOption` fields
changed (`--config KEY=VALUE,...`; ``base`` keeps LIBERO's options), the expert from the same
drawn initial states, one report per configuration (`agreement --from-reports` pairs each with
LIBERO's), and a line: successes, diverged, the steps they diverged at. Changed options are
not LIBERO's physics; a configuration that keeps every episode finite says where the
divergence comes from, and its agreement with LIBERO says what it costs.

Usage (GPU machine, after ``source benchmarks/gpu_setup.sh``; the task's export and draws
carried in ``OPENRAL_MJX_LIBERO_MODELS``):

    python3 benchmarks/libero_warp_options.py --out $OUT --config base ccd_iterations=200 \
        ccd_tolerance=1e-4 cone=pyramidal
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from openral_mjx.benchmarks.libero.mirror import scene as mirror_scene
from openral_mjx.evaluation import build_scene
from openral_mjx.evaluation.run import run_evaluation
from openral_mjx.policies import make_policy
from openral_mjx.report.io import save_report

# enum fields: the enum and its members' prefix (``cone=pyramidal`` is mjCONE_PYRAMIDAL)
ENUMS = {
    "cone": (mujoco.mjtCone, "mjCONE"),
    "integrator": (mujoco.mjtIntegrator, "mjINT"),
    "solver": (mujoco.mjtSolver, "mjSOL"),
}


def parse_config(text: str) -> dict[str, Any]:
    """``KEY=VALUE,...`` (``base``: none) as `mjOption` fields: numbers, or an enum's member
    name for `ENUMS` (``cone=pyramidal``), or ``disable=NAME`` (a `mjtDisableBit`, repeatable
    with ``+``: ``disable=warmstart+filterparent``)."""
    out: dict[str, Any] = {}
    if text == "base":
        return out
    for item in text.split(","):
        key, _, value = item.partition("=")
        if key in ENUMS:
            enum, prefix = ENUMS[key]
            out[key] = int(getattr(enum, f"{prefix}_{value.upper()}"))
        elif key == "disable":
            bits = (getattr(mujoco.mjtDisableBit, f"mjDSBL_{v.upper()}") for v in value.split("+"))
            out[key] = sum(int(b) for b in bits)
        else:
            out[key] = float(value) if any(c in value for c in ".e") else int(value)
    return out


def applied(changes: dict[str, Any]):
    """`physics_spec` with `changes` set on the spec's options (what the mirror compiles)."""
    original = mirror_scene.physics_spec

    def spec(*args: Any, **kwargs: Any) -> mujoco.MjSpec:
        s = original(*args, **kwargs)
        for key, value in changes.items():
            if key == "disable":
                s.option.disableflags |= value
            else:
                setattr(s.option, key, value)
        return s

    return spec


def run(args: argparse.Namespace, config: str) -> dict[str, Any]:
    changes = parse_config(config)
    original = mirror_scene.physics_spec
    mirror_scene.physics_spec = applied(changes)
    try:
        options = {"task": args.task, "protocol": "sampled", "sampled_states": args.seeds}
        scene = build_scene(
            "libero_mjx",
            options,
            backend=args.backend,
            n_envs=args.seeds,
            contacts_per_env=args.contacts,
        )
    finally:
        mirror_scene.physics_spec = original
    opt = scene.backend.mj_model.opt  # the changes reached the model the backend simulates
    for key, value in changes.items():
        have = opt.disableflags & value if key == "disable" else getattr(opt, key)
        assert np.isclose(float(have), float(value)), (key, have, value)
    start = time.perf_counter()
    with run_evaluation(
        scene,
        make_policy("libero-expert", scene),
        n_envs=args.seeds,
        n_episodes=args.seeds,
        max_steps=args.max_steps,
        command=f"libero_warp_options {config}",
    ) as ev:
        report = ev.report
    tag = config.replace("=", "-").replace(",", "_").replace("+", "-")
    save_report(
        report, args.out / f"{args.task.replace('/', '_')}_mirror_{args.backend}_{tag}.json"
    )
    eps = report.episodes
    diverged = [(e.metadata["seed"], e.steps) for e in eps if e.metadata.get("diverged")]
    firsts = [e.metadata["first_success_step"] for e in eps if e.success]
    row = {
        "config": config,
        "changes": changes,
        "successes": report.successes,
        "diverged": len(diverged),
        "diverged_seeds": [s for s, _ in diverged],
        "diverged_steps": sorted({n for _, n in diverged}),
        "median_success_step": float(np.median(firsts)) if firsts else None,
        "wall_s": round(time.perf_counter() - start, 1),
    }
    print(json.dumps(row), flush=True)
    return row


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--task", default="libero_10/0")
    p.add_argument("--seeds", type=int, default=200)
    p.add_argument("--contacts", type=int, default=512)
    p.add_argument("--backend", default="warp")
    p.add_argument("--max-steps", type=int, default=None, help="default: the task's")
    p.add_argument("--config", nargs="+", default=["base"])
    p.add_argument("--out", type=Path, default=Path("results"))
    args = p.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    rows = [run(args, c) for c in args.config]
    (args.out / "warp_options.json").write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
