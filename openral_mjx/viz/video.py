"""Episode videos: scene render | the policy's image inputs | joint plot, side by side, as MP4.

Frames are drawn on the host from an `EpisodeTrace`: each step's recorded state is loaded into
a private copy of the scene's `MjModel` (`Scene.pose_frame`), forwarded with `mj_forward` and
rendered from a named camera. The policy's image observations get a panel each, and none when
it has none (vector observations). The joint plot shows every joint-driving actuator's joint
position (solid) and, for position servos, its target (dashed: the action, clipped to the
control range), with a cursor at the current step. A header names the episode (scene, policy,
seed, outcome and its step, how it was re-simulated) and the current step. Encoded with PyAV
(H.264, yuv420p) at the control rate, one frame per control step, so it plays in real time.
"""

from __future__ import annotations

import copy
import dataclasses
import fractions
import functools
from collections.abc import Iterator
from pathlib import Path

import mujoco
import numpy as np

from openral_mjx.core.files import atomic_path
from openral_mjx.evaluation.replay import EpisodeTrace
from openral_mjx.physics.gl import FrameRenderer, camera_id
from openral_mjx.scenes.base import Scene

HEADER_H = 48
PANEL_W, PANEL_H = 448, 336  # multiples of 16: whole H.264 macroblocks


@dataclasses.dataclass(frozen=True)
class VideoInfo:
    """What was written: the file, its frame count and size, and its title."""

    path: Path
    frames: int
    width: int
    height: int
    fps: float
    title: str
    comment: str


@functools.cache
def _font(size: int):
    from matplotlib import font_manager
    from PIL import ImageFont

    return ImageFont.truetype(font_manager.findfont("DejaVu Sans"), size)


def _text(image: np.ndarray, lines: list[tuple[int, int, str, int]], fill=(235, 235, 235)) -> None:
    """Draw (x, y, text, size) lines onto an RGB uint8 image in place."""
    from PIL import Image, ImageDraw

    pil = Image.fromarray(image)
    draw = ImageDraw.Draw(pil)
    for x, y, text, size in lines:
        draw.text((x, y), text, font=_font(size), fill=fill)
    image[...] = np.asarray(pil)


def default_camera(scene: Scene) -> str:
    """The scene's `video_camera`, else the model's first camera."""
    model = scene.mj_model
    if scene.video_camera is not None:
        return scene.video_camera
    if model.ncam == 0:
        raise ValueError(f"scene {scene.name!r} has no camera to film")
    return model.camera(0).name


class JointPlot:
    """A joint-position plot of one episode, drawn once; frames add a cursor at their step."""

    def __init__(self, scene: Scene, trace: EpisodeTrace, width: int, height: int) -> None:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        m = scene.mj_model
        fig = Figure(figsize=(width / 100, height / 100), dpi=100)
        canvas = FigureCanvasAgg(fig)
        ax = fig.add_axes((0.14, 0.14, 0.83, 0.76))
        steps = np.arange(trace.steps + 1)
        qpos = trace.frame.get("qpos")
        colors = [f"C{i % 10}" for i in range(m.nu)]
        # A target per actuator only where the action is one (`Scene.action_size`'s default):
        # an end-effector action (LIBERO's 7-D OSC, MetaWorld's 4-D) is no joint's target.
        per_actuator = trace.action.ndim == 2 and trace.action.shape[1] == m.nu
        for a in range(m.nu):
            if qpos is None or m.actuator_trntype[a] != mujoco.mjtTrn.mjTRN_JOINT:
                continue
            joint = m.joint(int(m.actuator_trnid[a, 0]))
            q = qpos[:, int(joint.qposadr[0])]
            ax.plot(steps, q, color=colors[a], lw=1.3, label=joint.name)
            if per_actuator and _is_position_servo(m, a):
                target = trace.action[1:, a]
                if m.actuator_ctrllimited[a]:
                    target = np.clip(target, *m.actuator_ctrlrange[a])
                ax.plot(steps[1:], target, color=colors[a], lw=0.9, ls="--")
        ax.set_xlim(0, max(trace.steps, 1))
        ax.set_xlabel("control step", fontsize=8)
        ax.set_ylabel("joint position (rad / m)", fontsize=8)
        title = "joints: position (solid), target (dashed)" if per_actuator else "joint positions"
        ax.set_title(title, fontsize=9)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
        if ax.lines:
            ax.legend(fontsize=6, loc="upper right", ncol=2, framealpha=0.6)
        canvas.draw()
        self.image = np.asarray(canvas.buffer_rgba())[:, :, :3].copy()
        # Pixel columns of each step, and the axes' rows (display y runs bottom-up).
        self._cols = np.rint(ax.transData.transform(np.c_[steps, np.zeros_like(steps)])[:, 0])
        self._cols = self._cols.astype(int)
        box = ax.bbox
        self._rows = slice(height - int(box.y1), height - int(box.y0))

    def at(self, step: int) -> np.ndarray:
        frame = self.image.copy()
        col = self._cols[step]
        frame[self._rows, max(col - 1, 0) : col + 1] = (200, 30, 30)
        return frame


def _is_position_servo(m: mujoco.MjModel, a: int) -> bool:
    """An actuator whose control is a joint position target (MuJoCo's <position>)."""
    kp = m.actuator_gainprm[a, 0]
    return (
        m.actuator_biastype[a] == mujoco.mjtBias.mjBIAS_AFFINE
        and kp > 0
        and np.isclose(m.actuator_biasprm[a, 1], -kp)
    )


def _image_panel(images: np.ndarray, height: int, name: str) -> list[np.ndarray]:
    """One policy image observation per step as RGB panels of `height` rows: depth (H, W) in
    grey (near is bright, scaled over the episode), RGB (H, W, 3) in [0, 1] as is."""
    from PIL import Image

    images = np.asarray(images, np.float32)
    if images.ndim == 3:  # depth
        finite = images[np.isfinite(images)]
        far = float(finite.max()) if finite.size else 1.0
        grey = 1 - np.clip(np.nan_to_num(images, nan=far, posinf=far) / max(far, 1e-6), 0, 1)
        images = np.repeat(grey[..., None], 3, axis=-1)
    rgb = (np.clip(images, 0, 1) * 255).astype(np.uint8)
    h, w = rgb.shape[1:3]
    width = max(2, round(w * height / h / 2) * 2)
    panels = []
    for img in rgb:
        panel = np.asarray(Image.fromarray(img).resize((width, height), Image.NEAREST)).copy()
        _text(panel, [(6, 4, f"policy input: {name}", 12)])
        panels.append(panel)
    return panels


def episode_frames(
    scene: Scene,
    trace: EpisodeTrace,
    camera: str,
    gl: str,
    title: str,
    size: tuple[int, int] = (PANEL_W, PANEL_H),
) -> Iterator[np.ndarray]:
    """The video's frames (RGB uint8, one per step, `trace.steps + 1` of them)."""
    width, height = size
    model = copy.copy(scene.mj_model)
    cam = camera_id(model, camera)
    data = mujoco.MjData(model)
    plot = JointPlot(scene, trace, width, height)
    images = [_image_panel(v, height, k) for k, v in trace.images.items()]
    dt = scene.control_dt
    with FrameRenderer(model, width, height, gl) as renderer:
        for t in range(trace.steps + 1):
            scene.pose_frame(model, data, {k: v[t] for k, v in trace.frame.items()})
            mujoco.mj_forward(model, data)
            view = renderer.render(data, cam)
            _text(view, [(6, 4, f"camera: {camera}", 12)])
            body = np.concatenate([view, *(p[t] for p in images), plot.at(t)], axis=1)
            head = np.full((HEADER_H, body.shape[1], 3), 24, np.uint8)
            _text(
                head,
                [
                    (8, 3, title, 15),
                    (8, 25, trace.provenance(), 12),
                    (body.shape[1] - 190, 25, f"step {t:>4}/{trace.steps}  t={t * dt:5.2f} s", 12),
                ],
            )
            yield np.concatenate([head, body], axis=0)


def episode_title(scene: Scene, policy: str, trace: EpisodeTrace) -> str:
    """'tabletop_push/scripted  seed 12: failure at step 200'."""
    return f"{scene.name}/{policy}  seed {trace.seed}: {trace.outcome} at step {trace.steps}"


def write_mp4(path: Path, frames: Iterator[np.ndarray], fps: float, title: str, comment: str):
    """Encode RGB frames as H.264 MP4 at `path` (atomically); returns (frames, width, height)."""
    import av

    rate = fractions.Fraction(fps).limit_denominator(1000)
    count, shape = 0, (0, 0)
    with atomic_path(path) as tmp, av.open(str(tmp), "w", format="mp4") as out:
        out.metadata["title"] = title
        out.metadata["comment"] = comment
        stream = None
        for frame in frames:
            if stream is None:
                shape = frame.shape[:2]
                stream = out.add_stream("libx264", rate=rate)
                stream.height, stream.width = shape
                stream.pix_fmt = "yuv420p"
                stream.options = {"crf": "23", "preset": "veryfast"}
            out.mux(stream.encode(av.VideoFrame.from_ndarray(frame, format="rgb24")))
            count += 1
        if stream is not None:
            out.mux(stream.encode())
    return count, shape[1], shape[0]


def write_episode_video(
    path: Path,
    scene: Scene,
    policy: str,
    trace: EpisodeTrace,
    *,
    camera: str,
    gl: str,
) -> VideoInfo:
    """Render one episode to an MP4 at `path` (see the module docstring)."""
    title = episode_title(scene, policy, trace)
    comment = f"seed {trace.seed}; {trace.provenance()}"
    fps = 1 / scene.control_dt
    frames = episode_frames(scene, trace, camera, gl, title)
    n, width, height = write_mp4(path, frames, fps, title, comment)
    return VideoInfo(path, n, width, height, fps, title, comment)


def still(
    scene: Scene, policy: str, trace: EpisodeTrace, step: int, camera: str, gl: str
) -> np.ndarray:
    """One frame of an episode's video (RGB uint8), e.g. for a notebook or a README."""
    if not 0 <= step <= trace.steps:
        raise ValueError(f"step {step} is outside the episode's 0..{trace.steps}")
    frames = episode_frames(scene, trace, camera, gl, episode_title(scene, policy, trace))
    try:
        for t, frame in enumerate(frames):
            if t == step:
                return frame
    finally:
        frames.close()
    raise AssertionError("unreachable")


def image_png(image: np.ndarray) -> bytes:
    """An RGB uint8 image as PNG bytes."""
    import io

    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(image).save(buf, format="PNG")
    return buf.getvalue()
