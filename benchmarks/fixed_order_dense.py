"""The policy's fixed-order layers on this machine's default device (issue 38).

The evaluator's MLP (39-256-256-256-4, the MetaWorld mirror's random policy) through three
ways of computing its layers: `loop` (`fixed_order`'s elementwise multiply-add loop, the GPU's
path before 2026-11-28), `tiles` (`batch_invariant.rows_matmul`, the GPU's path now) and
`xla` (XLA's own matrix product, not batch-invariant: the speed to aim at). Per way: one
batched forward pass's time, and whether a row's actions are the same bits in a small batch
(`--small` rows) and shifted by `--shift` rows as in the full batch. `max_diff_from_loop`:
how far its actions are from the loop's. One JSON line per way on stdout and in `--out`.

    python benchmarks/fixed_order_dense.py --n 65536 --out fixed_order_dense.jsonl
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from openral_mjx.core import batch_invariant as bi
from openral_mjx.core import fixed_order as fo
from openral_mjx.policies.mlp import MlpConfig, init_params

CONFIG = MlpConfig(
    obs_size=39,
    action_size=4,
    action_offset=(0.0,) * 4,
    action_scale=(1.0,) * 4,
    hidden=(256, 256, 256),
)
WAYS = {
    "loop": fo.loop_rows,
    "tiles": lambda x, w, b: bi.rows_matmul(x, w, b, interpret=jax.default_backend() == "cpu"),
    "xla": lambda x, w, b: x @ w + b,
}


def forward(way: str):
    """The batched forward pass with every layer computed `way`."""
    params = init_params(CONFIG, jax.random.PRNGKey(0))["actor"]
    dense = WAYS[way]

    def run(obs: jax.Array) -> jax.Array:
        x = obs
        layers = params["params"]
        for i in range(len(CONFIG.hidden) + 1):
            p = layers[f"_Dense_{i}"]
            x = dense(x, p["kernel"], p["bias"])
            x = jax.nn.silu(x) if i < len(CONFIG.hidden) else x
        return x

    return jax.jit(run)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=65536)
    parser.add_argument("--small", type=int, default=5)
    parser.add_argument("--shift", type=int, default=3)
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--out", type=Path)
    parser.add_argument(
        "--tiles",
        nargs="+",
        default=[],
        metavar="ROWS,COLS,DEPTH,WARPS",
        help="more `tiles` rows with these tile sizes (`batch_invariant`'s constants)",
    )
    args = parser.parse_args()
    obs = jax.random.normal(jax.random.PRNGKey(1), (args.n, CONFIG.obs_size), jnp.float32)
    device = str(jax.devices()[0].device_kind)
    rows, loop_out = [], None
    tiles = (bi.ROWS, bi.MAX_COLS, bi.DEPTH, bi.WARPS)
    runs = [(way, tiles) for way in WAYS]
    runs += [("tiles", tuple(int(v) for v in t.split(","))) for t in args.tiles]
    for way, (bi.ROWS, bi.MAX_COLS, bi.DEPTH, bi.WARPS) in runs:
        fn = forward(way)
        t = time.perf_counter()
        compiled = fn.lower(obs).compile()
        compile_s = time.perf_counter() - t
        out = np.asarray(compiled(obs))
        t = time.perf_counter()
        for _ in range(args.repeats):
            jax.block_until_ready(compiled(obs))
        ms = (time.perf_counter() - t) / args.repeats * 1e3
        small = np.asarray(fn(obs[: args.small]))
        shifted = np.asarray(fn(obs[args.shift : args.shift + 1000]))
        loop_out = out if loop_out is None else loop_out
        rows.append(
            {
                "device": device,
                "n": args.n,
                "way": way,
                **({"tiles": [bi.ROWS, bi.MAX_COLS, bi.DEPTH, bi.WARPS]} if way == "tiles" else {}),
                "compile_s": round(compile_s, 3),
                "forward_ms": round(ms, 4),
                "small_batch_same_rows": bool(np.array_equal(small, out[: args.small])),
                "shifted_rows_same": bool(
                    np.array_equal(shifted, out[args.shift : args.shift + 1000])
                ),
                "max_diff_from_loop": float(np.max(np.abs(out - loop_out))),
            }
        )
        print(json.dumps(rows[-1]), flush=True)
    if args.out:
        with args.out.open("a") as f:
            f.writelines(json.dumps(r) + "\n" for r in rows)


if __name__ == "__main__":
    main()
