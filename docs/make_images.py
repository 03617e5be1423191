"""Regenerate the images of the README and docs from the quick-start run (1,024 seeds,
scripted expert, `c`): the success-by-factor plot and a still from the video of the first
failed episode.

    python docs/make_images.py
"""

from __future__ import annotations

from pathlib import Path

from openral_mjx.evaluation import run_evaluation
from openral_mjx.evaluation.replay import choose_seeds, trace_episodes
from openral_mjx.physics.gl import gl_backend
from openral_mjx.viz.plots import save_png, success_by_factor
from openral_mjx.viz.video import default_camera, image_png, still

DOCS = Path(__file__).parent


def main() -> None:
    evaluation = run_evaluation("tabletop_push", "scripted", n_envs=1024, backend="c")
    print(evaluation.report.summary())
    save_png(success_by_factor(evaluation.report), DOCS / "success_by_factor.png")
    [trace] = trace_episodes(evaluation, choose_seeds(evaluation, failures=1))
    scene = evaluation.scene
    frame = still(scene, "scripted", trace, 120, default_camera(scene), gl_backend())
    (DOCS / "video_still.png").write_bytes(image_png(frame))
    print(f"seed {trace.seed}: {trace.outcome} at step {trace.steps}; {trace.provenance()}")


if __name__ == "__main__":
    main()
