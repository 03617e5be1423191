"""The LIBERO mirror's camera images against LIBERO's own, on the same states.

LIBERO (in its worker environment, robosuite 1.4 on mujoco 3.8.1) plays a fixed action
sequence from an initial state and hands back its observation images (``image``: agentview,
``wrist_image``: robot0_eye_in_hand, upright as the host scene gives them) with the state each
was drawn from. The mirror (`libero_mjx` with ``image_size``) draws the same states on backend
`c` (MuJoCo's OpenGL renderer) or `warp` (MuJoCo-Warp's batch renderer). Per camera: the
share of pixels whose every channel is within 8/255, the mean absolute error (in 1/255) and
SSIM (Wang et al. 2004), against LIBERO's images or, with ``--against c``, against the
mirror's own `c` images of the same states (what `warp` changes of MuJoCo's renderer).

``python -m openral_mjx.benchmarks.libero.render --tasks libero_spatial/0 --seeds 0 1 2``
prints the table (markdown) and writes its rows as JSON with ``--out``; ``--backend warp``
draws the mirror's images on `warp` (``--image-samples 2``: 2 x 2 sub-pixel samples).
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from scipy import ndimage

from openral_mjx.benchmarks.libero.assets import TIMEOUT_S, load_task, task_worker
from openral_mjx.benchmarks.libero.mirror import LiberoMjx, LiberoMjxOptions
from openral_mjx.benchmarks.libero.mirror.scene import CAMERAS, camera_images
from openral_mjx.core.errors import ConfigError
from openral_mjx.core.files import write_text_atomic
from openral_mjx.scenes import scene_settings

TOL = 8  # per channel, in 1/255
BACKENDS = ("c", "warp")  # the mirror's backends that render its cameras
SSIM_SIGMA = 1.5  # Wang et al.'s Gaussian window: sigma 1.5, 11 x 11
SSIM_RADIUS = 5


def ssim(a: np.ndarray, b: np.ndarray, data_range: float = 255.0) -> float:
    """Mean SSIM of two images (H, W) or (H, W, C) (channels averaged), Wang et al. 2004:
    Gaussian-weighted local means, variances and covariance (sigma 1.5, 11 x 11 window),
    K1 = 0.01, K2 = 0.03, averaged over the windows that fit inside the image (all pixels,
    borders reflected, where none fits)."""
    if a.shape != b.shape:
        raise ValueError(f"ssim of images of different shapes {a.shape} and {b.shape}")
    x, y = np.asarray(a, np.float64), np.asarray(b, np.float64)
    if x.ndim == 2:
        x, y = x[..., None], y[..., None]
    c1, c2 = (0.01 * data_range) ** 2, (0.03 * data_range) ** 2
    truncate = SSIM_RADIUS / SSIM_SIGMA
    sigma = (SSIM_SIGMA, SSIM_SIGMA, 0.0)  # per channel, no mixing

    def blur(z: np.ndarray) -> np.ndarray:
        return ndimage.gaussian_filter(z, sigma, mode="reflect", truncate=truncate)

    mx, my = blur(x), blur(y)
    vx, vy, cxy = blur(x * x) - mx * mx, blur(y * y) - my * my, blur(x * y) - mx * my
    num = (2 * mx * my + c1) * (2 * cxy + c2)
    den = (mx * mx + my * my + c1) * (vx + vy + c2)
    smap = num / den
    r = SSIM_RADIUS
    if min(x.shape[:2]) > 2 * r:
        smap = smap[r:-r, r:-r]
    return float(smap.mean())


def pixel_agreement(ours: np.ndarray, ref: np.ndarray, tol: int = TOL) -> dict[str, float]:
    """Images (n, H, W, 3) uint8 against references: the share of pixels with every channel
    within `tol`/255, the mean absolute error in 1/255, the mean SSIM."""
    err = np.abs(ours.astype(np.int32) - ref.astype(np.int32))
    return {
        "within": float(np.mean(np.all(err <= tol, axis=-1))),
        "mae": float(err.mean()),
        "ssim": float(np.mean([ssim(o, r) for o, r in zip(ours, ref, strict=True)])),
    }


def actions_for(seed: int, steps: int) -> np.ndarray:
    """The fixed action sequence played from seed `seed`: uniform in [-1, 1]^7 (the arm
    moves several centimetres, the gripper opens and closes)."""
    return np.random.default_rng(seed).uniform(-1.0, 1.0, (steps, 7))


def libero_states(
    task: str, seeds: Sequence[int], steps: int, every: int, image_size: int, drawn: int
) -> dict[str, np.ndarray]:
    """LIBERO's images and drawn states (`TaskExport.camera_states`) at steps 0, `every`,
    ... `steps` of `actions_for(seed)` from each seed's initial state, stacked."""
    out: dict[str, list[np.ndarray]] = {}
    with task_worker(task, image_size) as (worker, _):
        for seed in seeds:
            kwargs = {"init": int(seed) % 50, "actions": actions_for(seed, steps), "drawn": drawn}
            got = worker.call(
                {"op": "call", "method": "camera_states", "kwargs": kwargs}, TIMEOUT_S
            )
            for k, v in got.items():
                out.setdefault(k, []).append(np.asarray(v)[::every])
            n = len(out["qpos"][-1])
            out.setdefault("init", []).append(np.full(n, int(seed) % 50, np.int32))
    return {k: np.concatenate(v) for k, v in out.items()}


def mirror_images(
    scene: LiberoMjx, qpos: np.ndarray, qvel: np.ndarray, init: np.ndarray
) -> dict[str, np.ndarray]:
    """The mirror's observation images (uint8, as its observation holds them) of states, each
    with its initial state's fixtures (`init`)."""

    def draw(q: jax.Array, v: jax.Array, i: jax.Array) -> dict[str, jax.Array]:
        return camera_images(scene.backend.init(q, v, scene.model_fields(i)).quantities)

    f32 = lambda x: jnp.asarray(x, jnp.float32)  # noqa: E731
    images = jax.jit(jax.vmap(draw))(f32(qpos), f32(qvel), jnp.asarray(init, jnp.int32))
    return {k: np.asarray(v) for k, v in images.items()}


def backend_images(
    task: str, backend: str, image_size: int, ref: dict[str, np.ndarray], samples: int = 1
) -> dict[str, np.ndarray]:
    """The mirror's images on `backend` of the states of `ref` (`libero_states`), `samples`
    sub-pixel samples per axis (`warp` only)."""
    settings = scene_settings("libero_mjx", batch_size=max(1, len(ref["qpos"])))
    options = LiberoMjxOptions(task=task, image_size=image_size, image_samples=samples)
    scene = LiberoMjx(options, backend=backend, settings=settings)
    try:
        return mirror_images(scene, ref["qpos"], ref["qvel"], ref["init"])
    finally:
        close = getattr(scene.backend, "close", None)  # `c`'s thread pools and GL contexts
        if close is not None:
            close()


def task_rows(
    task: str,
    seeds: Sequence[int],
    steps: int = 20,
    every: int = 10,
    image_size: int = 128,
    backend: str = "c",
    against: str = "libero",
    samples: int = 1,
) -> list[dict[str, Any]]:
    """One row per camera of `task`: the mirror's images on `backend` against LIBERO's
    (`against` ``libero``) or the mirror's on another backend (``c``), over seeds x steps 0,
    `every`, ... `steps`."""
    if backend not in BACKENDS or against not in ("libero", *BACKENDS):
        raise ConfigError(
            f"render backend={backend!r} against={against!r}; valid: backends {BACKENDS}, "
            f"against libero or one of them"
        )
    # robosuite draws the state that physics step `observed - 1` (1-based) ends in
    drawn = int(load_task(task).meta["observation_substep"]) - 1
    ref = libero_states(task, seeds, steps, every, image_size, drawn)
    samples = samples if backend == "warp" else 1  # `c` draws with MuJoCo's multisampling
    ours = backend_images(task, backend, image_size, ref, samples)
    theirs = ref if against == "libero" else backend_images(task, against, image_size, ref)
    return [
        {
            "task": task,
            "camera": key,
            "mjcf_camera": cam,
            "image_size": image_size,
            "backend": backend,
            "samples": samples,
            "against": against,
            "states": len(ref["qpos"]),
            **pixel_agreement(ours[key], theirs[key]),
        }
        for key, cam in CAMERAS.items()
    ]


def format_table(rows: Sequence[dict[str, Any]]) -> str:
    """The pixel agreement table in markdown."""
    lines = [
        f"| task | camera | backend | against | states | pixels within {TOL}/255 "
        "| MAE (1/255) | SSIM |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| `{r['task']}` | `{r['camera']}` | `{r.get('backend', 'c')}` | "
            f"{r.get('against', 'libero')} | {r['states']} | {100 * r['within']:.2f}% | "
            f"{r['mae']:.2f} | {r['ssim']:.4f} |"
        )
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> None:
    ap = argparse.ArgumentParser(
        prog="python -m openral_mjx.benchmarks.libero.render",
        description="The mirror's camera images against LIBERO's on the same states.",
    )
    ap.add_argument("--tasks", nargs="+", required=True, help="SUITE/INDEX ...")
    ap.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    ap.add_argument("--steps", type=int, default=20, help="actions played per seed")
    ap.add_argument("--every", type=int, default=10, help="compare every this many steps")
    ap.add_argument("--image-size", type=int, default=128)
    ap.add_argument("--backend", choices=BACKENDS, default="c", help="the mirror's renderer")
    ap.add_argument(
        "--against",
        choices=("libero", *BACKENDS),
        default="libero",
        help="compare with LIBERO's images or the mirror's on this backend",
    )
    ap.add_argument(
        "--image-samples", type=int, default=1, help="warp's sub-pixel samples per axis"
    )
    ap.add_argument("--out", type=Path, default=None, help="JSON file for the rows")
    a = ap.parse_args(argv)
    rows: list[dict[str, Any]] = []
    for task in a.tasks:
        rows += task_rows(
            task, a.seeds, a.steps, a.every, a.image_size, a.backend, a.against, a.image_samples
        )
        print("\n".join(format_table(rows).splitlines()[-2:]), flush=True)
        if a.out is not None:
            write_text_atomic(a.out, json.dumps(rows, indent=1))
    print(format_table(rows))


if __name__ == "__main__":
    main()
