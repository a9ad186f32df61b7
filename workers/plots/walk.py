"""Provides the pictures of a simulated walk: the robot rendered by MuJoCo (an animated GIF
and a still), the body's path on the floor and each leg's floor contacts over time.

MuJoCo renders offscreen through OpenGL: set `MUJOCO_GL=osmesa` (Debian's `libosmesa6`) or
`egl` before the first `import mujoco` of the process.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from PIL import Image

from linkevo.sim.robot import LEG_SLOTS
from linkevo.sim.walk import Walk
from linkevo.workers.store.artifacts import atomic_path


def render_frames(
    walk: Walk, *, seconds: float, fps: float = 15.0, size: tuple[int, int] = (480, 270)
) -> list[np.ndarray]:
    """Returns (H, W, 3) uint8 frames of the walk's first `seconds`, the camera following
    the frame from the front left."""
    import mujoco

    if walk.model is None or "qpos" not in walk.trace:
        raise ValueError("this walk has no model or state trace to render")
    model, trace = walk.model, walk.trace
    data = mujoco.MjData(model)
    camera = mujoco.MjvCamera()
    camera.type = mujoco.mjtCamera.mjCAMERA_TRACKING
    camera.trackbodyid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "frame")
    camera.distance, camera.azimuth, camera.elevation = 1.1, 135.0, -18.0
    times = np.arange(0.0, min(seconds, float(trace["t"][-1])), 1.0 / fps)
    rows = np.searchsorted(trace["t"], times)
    frames = []
    with mujoco.Renderer(model, height=size[1], width=size[0]) as renderer:
        for row in rows:
            data.qpos[:] = trace["qpos"][row]
            mujoco.mj_forward(model, data)
            renderer.update_scene(data, camera=camera)
            frames.append(renderer.render().copy())
    return frames


def write_gif(frames: list[np.ndarray], path: Path, fps: float = 15.0) -> Path:
    """Writes frames as a looping animated GIF (atomically) and returns the path."""
    palette = Image.Quantize.MEDIANCUT
    images = [Image.fromarray(f).quantize(colors=96, method=palette) for f in frames]
    with atomic_path(path) as tmp:
        images[0].save(
            tmp, format="GIF", save_all=True, append_images=images[1:],
            duration=round(1000 / fps), loop=0, optimize=True,
        )  # fmt: skip
    return path


def write_still(frame: np.ndarray, path: Path) -> Path:
    """Writes one frame as PNG (atomically) and returns the path."""
    with atomic_path(path) as tmp:
        Image.fromarray(frame).save(tmp, format="PNG")
    return path


def draw_body_path(walk: Walk, path: Path, title: str = "") -> Path:
    """Draws the frame's path on the floor (top view, cm), start and end marked, with the
    starting heading as an arrow; returns the path."""
    body = walk.trace["body"][:, :2] * 100
    fig = Figure(figsize=(6, 3.2), dpi=110)
    ax = fig.add_subplot()
    ax.plot(body[:, 0], body[:, 1], color="#1f6f8b", lw=2)
    ax.plot(*body[0], "o", color="#2a9d8f", label="start")
    ax.plot(*body[-1], "s", color="#e76f51", label=f"end: {walk.distance_m * 100:.1f} cm ahead")
    ax.annotate("", xy=body[0] + [8, 0], xytext=body[0], arrowprops={"arrowstyle": "->"})
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (cm), the heading at the start")
    ax.set_ylabel("y (cm)")
    ax.set_title(title or "the body's path on the floor", fontsize=10)
    ax.legend(loc="best", fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    return path


def draw_contacts(walk: Walk, path: Path, seconds: float = 5.0, title: str = "") -> Path:
    """Draws each leg's floor contact over the walk's first `seconds` (a bar where the leg
    touches the floor), the two tripods in two colours; returns the path."""
    t, contact = walk.trace["t"], walk.trace["contact"]
    keep = t <= seconds
    t, contact = t[keep], contact[keep]
    step = float(np.median(np.diff(t))) if len(t) > 1 else 0.02
    fig = Figure(figsize=(7, 2.8), dpi=110)
    ax = fig.add_subplot()
    phases = walk.trace["phase"][0] % (2 * np.pi)
    for i in range(len(LEG_SLOTS)):
        down = np.flatnonzero(contact[:, i])
        colour = "#264653" if abs(phases[i] - np.pi) > np.pi / 2 else "#e9c46a"
        ax.broken_barh([(t[k], step) for k in down], (i - 0.4, 0.8), color=colour)
    ax.set_yticks(range(len(LEG_SLOTS)), LEG_SLOTS, fontsize=8)
    ax.set_xlabel("time (s)")
    ax.set_xlim(0, seconds)
    ax.set_title(title or "foot contacts per leg (the two tripods in two colours)", fontsize=10)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    return path
