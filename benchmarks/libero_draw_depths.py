"""How deep LIBERO's drawn initial states start objects inside others (issue 37).

Per task whose mass-seed draws are in the export cache (`assets.load_sampled`'s
``sampled.npz``), the first 20 drawn states in the mirror's model (MuJoCo C, fixtures placed
per seed): the deepest contact and how many seeds start deeper than 1 cm. LIBERO's reset
draws objects into their BDDL regions without a settle, so an object started inside the table
is launched by the settle (`libero_10/1`'s milk carton, to 1 m), and where it lands is chaotic:
the tasks where per-seed agreement is limited by LIBERO's own draw.

Usage: python benchmarks/libero_draw_depths.py
"""

from __future__ import annotations

import glob
from pathlib import Path

import mujoco
import numpy as np

from openral_mjx.benchmarks.libero.assets import _read_sampled, load_task, models_root, physics_spec

SEEDS = 20
DEEP = 0.01  # m


def depths(task: str, draws: dict[str, np.ndarray]) -> np.ndarray:
    """The deepest contact (negative: penetration, m) of each of the first `SEEDS` draws."""
    m = physics_spec(load_task(task)).compile()
    d = mujoco.MjData(m)
    ids = draws["fixture_ids"]
    out = []
    for seed in range(min(SEEDS, len(draws["states"]))):
        m.body_pos[ids], m.body_quat[ids] = draws["fixture_pos"][seed], draws["fixture_quat"][seed]
        d.qpos[:] = draws["states"][seed][1 : 1 + m.nq]
        mujoco.mj_forward(m, d)
        out.append(min((float(d.contact[i].dist) for i in range(d.ncon)), default=0.0))
    return np.array(out)


def main() -> None:
    root = models_root()
    for f in sorted(glob.glob(str(root / "*" / "*" / "sampled.npz"))):
        task = "/".join(Path(f).parts[-3:-1])
        draws = _read_sampled(Path(f))
        if draws is None:
            continue
        w = depths(task, draws)
        print(
            f"{task}: deepest {100 * w.min():.2f} cm; {int((w < -DEEP).sum())} of {len(w)} "
            f"seeds deeper than {100 * DEEP:g} cm",
            flush=True,
        )


if __name__ == "__main__":
    main()
