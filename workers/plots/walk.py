"""Provides the pictures of a simulated walk: the robot drawn from the recorded walk (an
animated GIF and a still), the body's path on the floor and each leg's floor contacts over
time.

The robot is drawn with matplotlib from the walk's state trace, not by MuJoCo's OpenGL
renderer: MuJoCo places every geom (`mj_kinematics`, no OpenGL), and each frame projects
the beams (capsules), spheres, the frame's box and a chequered floor through a perspective
camera that follows the frame, farthest first. So pictures need no OpenGL library (a fresh
machine has neither OSMesa nor EGL) and look the same on every machine.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection, PolyCollection
from matplotlib.figure import Figure
from PIL import Image

from linkevo.sim.robot.hexapod import LEG_SLOTS
from linkevo.sim.robot.walking import Walk
from linkevo.workers.store.artifacts import atomic_path

CAMERA = {"distance": 1.1, "azimuth_deg": 45.0, "elevation_deg": 18.0, "fov_deg": 45.0}
"""The camera: this far from the frame (m), from the front left (azimuth from the robot's
+x, its front), this high above the floor's plane, with this vertical field of view."""
FLOOR_SQUARE_M = 0.1
_BEAM, _CRANK, _FRAME = "#7d828c", "#d99a1a", "#333f4c"
_FLOOR = ("#d1d1c7", "#adada3")


class _Camera:
    """A perspective camera looking at `target` from `eye`, z up."""

    def __init__(self, target: np.ndarray, size: tuple[int, int]) -> None:
        az, el = math.radians(CAMERA["azimuth_deg"]), math.radians(CAMERA["elevation_deg"])
        offset = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
        self.eye = target + CAMERA["distance"] * offset
        forward = -offset
        right = np.cross(forward, [0.0, 0.0, 1.0])
        right /= np.linalg.norm(right)
        self.axes = np.stack([right, np.cross(right, forward), forward])  # (3, 3) rows
        self.focal = size[1] / 2 / math.tan(math.radians(CAMERA["fov_deg"]) / 2)
        self.centre = np.array(size, dtype=float) / 2

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Returns (..., 2) pixel coordinates (y up) and (...) depths of points (..., 3)."""
        local = (points - self.eye) @ self.axes.T
        depth = np.maximum(local[..., 2], 1e-3)
        return self.centre + self.focal * local[..., :2] / depth[..., None], local[..., 2]


def render_frames(
    walk: Walk, *, seconds: float, fps: float = 15.0, size: tuple[int, int] = (480, 270)
) -> list[np.ndarray]:
    """Returns (H, W, 3) uint8 frames of the walk's first `seconds`, the camera following
    the frame from the front left."""
    import mujoco

    if walk.model is None or "qpos" not in walk.trace:
        raise ValueError("this walk has no model or state trace to draw")
    model, trace = walk.model, walk.trace
    data = mujoco.MjData(model)
    frame_body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "frame")
    times = np.arange(0.0, min(seconds, float(trace["t"][-1])), 1.0 / fps)
    rows = np.searchsorted(trace["t"], times)
    fig = Figure(figsize=(size[0] / 100, size[1] / 100), dpi=100, facecolor="#dfe6ec")
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_axes((0, 0, 1, 1))
    frames = []
    for row in rows:
        data.qpos[:] = trace["qpos"][row]
        mujoco.mj_kinematics(model, data)
        ax.clear()
        _draw_scene(ax, model, data, _Camera(data.xpos[frame_body].copy(), size), size)
        canvas.draw()
        frames.append(np.asarray(canvas.buffer_rgba())[..., :3].copy())
    return frames


def _draw_scene(ax, model, data, camera: _Camera, size: tuple[int, int]) -> None:
    """Draws the floor, then every geom farthest first, on axes spanning the image."""
    import mujoco

    ax.set_xlim(0, size[0])
    ax.set_ylim(0, size[1])
    ax.set_axis_off()
    ax.add_collection(_floor(camera))
    shapes = []  # (depth, kind, points (K, 2), width px, colour)
    frame_geom = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "frame")
    crank_bodies = {
        mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, f"{s}/{name}")
        for s in LEG_SLOTS
        for name in ("part0", "crank")
    }
    for g in range(model.ngeom):
        kind = mujoco.mjtGeom(int(model.geom_type[g]))  # numpy ints never equal the enum
        centre, mat = data.geom_xpos[g], data.geom_xmat[g].reshape(3, 3)
        if kind == mujoco.mjtGeom.mjGEOM_BOX:
            for face in _box_faces(centre, mat, model.geom_size[g]):
                points, depth = camera.project(face)
                shade = 0.55 + 0.45 * abs(np.cross(face[1] - face[0], face[2] - face[0])[2]) / (
                    np.linalg.norm(np.cross(face[1] - face[0], face[2] - face[0])) + 1e-12
                )
                colour = _FRAME if g == frame_geom else _BEAM
                shapes.append((depth.mean(), "poly", points, 0.0, _shade(colour, shade)))
        elif kind in (mujoco.mjtGeom.mjGEOM_CAPSULE, mujoco.mjtGeom.mjGEOM_SPHERE):
            half = model.geom_size[g, 1] if kind == mujoco.mjtGeom.mjGEOM_CAPSULE else 0.0
            ends = centre + np.outer([-half, half], mat[:, 2])
            points, depth = camera.project(ends)
            width = 2 * model.geom_size[g, 0] * camera.focal / depth.mean() * 0.72  # px -> pt
            colour = _CRANK if model.geom_bodyid[g] in crank_bodies else _BEAM
            shapes.append((depth.mean(), "line", points, width, colour))
    shapes.sort(key=lambda s: -s[0])
    for _, kind, points, width, colour in shapes:
        if kind == "poly":
            ax.add_collection(PolyCollection([points], facecolors=colour, edgecolors="none"))
        else:
            ax.add_collection(
                LineCollection(
                    [points], linewidths=max(width, 0.6), colors=colour, capstyle="round"
                )
            )


def _floor(camera: _Camera) -> PolyCollection:
    """The chequered floor (`FLOOR_SQUARE_M` squares) around the point the camera sees."""
    look = camera.eye + camera.axes[2] * CAMERA["distance"]
    span = math.ceil(2.0 / FLOOR_SQUARE_M)
    i0, j0 = (np.floor(look[:2] / FLOOR_SQUARE_M)).astype(int)
    polygons, colours = [], []
    for i in range(i0 - span, i0 + span):
        for j in range(j0 - span, j0 + span):
            corners = np.array([[i, j], [i + 1, j], [i + 1, j + 1], [i, j + 1]], dtype=float)
            world = np.column_stack([corners * FLOOR_SQUARE_M, np.zeros(4)])
            local = (world - camera.eye) @ camera.axes.T
            if (local[:, 2] < 0.05).any():  # behind or at the camera: not drawn
                continue
            polygons.append(camera.project(world)[0])
            colours.append(_FLOOR[(i + j) % 2])
    return PolyCollection(polygons, facecolors=colours, edgecolors="none")


def _box_faces(centre: np.ndarray, mat: np.ndarray, half: np.ndarray) -> list[np.ndarray]:
    """Returns the six (4, 3) faces of a box."""
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    corners = centre + (signs * half) @ mat.T  # (8, 3), corner k has the signs of row k
    faces = []
    for axis in range(3):
        for side in (-1, 1):
            on = [k for k in range(8) if signs[k, axis] == side]
            a, b = [(axis + 1) % 3, (axis + 2) % 3]
            on.sort(key=lambda k: math.atan2(signs[k, b], signs[k, a]))
            faces.append(corners[on])
    return faces


def _shade(colour: str, light: float) -> tuple[float, float, float]:
    rgb = np.array([int(colour[i : i + 2], 16) for i in (1, 3, 5)]) / 255
    return tuple(np.clip(rgb * light, 0, 1))


def write_gif(frames: list[np.ndarray], path: Path, fps: float = 15.0) -> Path:
    """Writes frames as a looping animated GIF (atomically) and returns the path."""
    palette = Image.Quantize.MEDIANCUT
    images = [Image.fromarray(f).quantize(colors=96, method=palette) for f in frames]
    with atomic_path(path) as tmp:
        images[0].save(
            tmp,
            format="GIF",
            save_all=True,
            append_images=images[1:],
            duration=round(1000 / fps),
            loop=0,
            optimize=True,
        )
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
