"""Stick-figure animations: side by side panels (ground truth, reconstruction), GIF and MP4.

Each panel follows its own figure (the pelvis stays in the middle, the floor grid scrolls under
it), seen by an orthographic camera from ``azimuth`` about the vertical and ``elevation`` above
the horizon. Frames are drawn with matplotlib (Agg, so no display is needed) and written with
imageio: MP4 through imageio-ffmpeg's bundled ffmpeg binary, GIF through Pillow.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from imuloco.core.motion import Motion
from imuloco.core.skeleton import Skeleton
from imuloco.io.atomic import atomic_path, check_output
from imuloco.ops.filters import gaussian_smooth
from imuloco.ops.heading import heading_from_hips

SIDE_COLORS = {"left": "#1f77b4", "right": "#d62728", "center": "#444444"}
PANEL_SIZE = (320, 384)  # pixels (width, height); multiples of 16 keep H.264 from rescaling
GRID_STEP = 0.5  # metres between floor grid lines
GRID_HALF = 3.0  # metres of floor drawn around the pelvis
GIF_COLORS = 32  # palette size: a stick figure on white needs few colours


def joint_sides(skeleton: Skeleton) -> list[str]:
    """``"left"``, ``"right"`` or ``"center"`` per joint, from the body map: a joint is on a
    side when it or an ancestor stands for a part of that side, or when all its children are
    on that side (a clavicle)."""
    sides = ["center"] * skeleton.num_joints
    mapped = {skeleton.index(name): part.split("_")[0]
              for part, name in (skeleton.body_map or {}).items()
              if part.startswith(("left_", "right_"))}
    for j in range(skeleton.num_joints):  # parents precede children
        p = int(skeleton.parents[j])
        sides[j] = mapped.get(j, sides[p] if p >= 0 else "center")
    for j in reversed(range(skeleton.num_joints)):
        kids = {sides[c] for c in skeleton.children(j)}
        if sides[j] == "center" and j > 0 and len(kids) == 1 and kids != {"center"}:
            sides[j] = kids.pop()
    return sides


def camera_axes(azimuth: float, elevation: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Screen right, screen up and towards-the-camera unit vectors (3,) of an orthographic
    camera at ``azimuth`` radians about +Y (0: on +Z looking towards -Z) and ``elevation``
    radians above the horizon."""
    right = np.array([np.cos(azimuth), 0.0, -np.sin(azimuth)])
    back = np.array([np.sin(azimuth), 0.0, np.cos(azimuth)])
    up = np.array([0.0, 1.0, 0.0])
    to_camera = np.cos(elevation) * back + np.sin(elevation) * up
    screen_up = -np.sin(elevation) * back + np.cos(elevation) * up
    return right, screen_up, to_camera


def project(points: np.ndarray, azimuth: float, elevation: float) -> np.ndarray:
    """Orthographic projection of world points (Y up).

    Parameters
    ----------
    points : ndarray, shape (..., 3), metres.
    azimuth, elevation : radians, see :func:`camera_axes`.

    Returns
    -------
    ndarray, shape (..., 2): screen x (right) and y (up), metres.
    """
    right, up, _ = camera_axes(azimuth, elevation)
    points = np.asarray(points, dtype=np.float64)
    return np.stack([points @ right, points @ up], axis=-1)


def follow_azimuth(motion: Motion, offset_deg: float = 30.0, sigma_s: float = 1.0
                   ) -> np.ndarray:
    """Per-frame camera azimuth (T,) that keeps seeing the figure from its left side, turned
    ``offset_deg`` towards its front, as it turns: the hip-line heading, unwrapped and
    smoothed over ``sigma_s`` seconds (so the camera does not sway with the pelvis)."""
    pos = motion.part_positions(["left_hip", "right_hip"])
    theta = np.unwrap(heading_from_hips(pos[:, 0], pos[:, 1]))
    if motion.num_frames > 1:
        theta = gaussian_smooth(theta, sigma_s * motion.fps)
    return theta + np.pi / 2 - np.radians(offset_deg)


def _bones(skeleton: Skeleton) -> np.ndarray:
    """(B, 2) parent-child joint index pairs."""
    return np.array([(int(p), j) for j, p in enumerate(skeleton.parents) if p >= 0])


class StickRenderer:
    """Draws frames of one or more motions side by side into RGB arrays.

    Parameters
    ----------
    motions : motions on any skeletons, drawn left to right (all frames are drawn at the
        times of the first: each motion's frame ``round(t * fps)``, clamped).
    titles : one caption per panel.
    azimuth, elevation : camera in radians (azimuth ``None``: each panel's camera follows its
        figure's heading, :func:`follow_azimuth`; elevation 0.25 rad).
    panel_size : (width, height) pixels per panel.
    """

    def __init__(self, motions: Sequence[Motion], titles: Sequence[str] | None = None,
                 azimuth: float | None = None, elevation: float = 0.25,
                 panel_size: tuple[int, int] = PANEL_SIZE) -> None:
        import matplotlib  # the [viz] extra's

        matplotlib.use("Agg")
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.collections import LineCollection
        from matplotlib.figure import Figure

        if not motions:
            raise ValueError("StickRenderer: no motion to draw")
        self.motions = list(motions)
        self.titles = list(titles) if titles is not None else [m.name for m in self.motions]
        self.azimuths = [follow_azimuth(m) if azimuth is None else np.full(m.num_frames, azimuth)
                         for m in self.motions]
        self.elevation = elevation
        self.positions = [m.positions() for m in self.motions]
        self.bones = [_bones(m.skeleton) for m in self.motions]
        self.floors = [float(np.percentile(p[:, :, 1].min(axis=1), 5)) for p in self.positions]
        self.fps = self.motions[0].fps
        self.num_frames = self.motions[0].num_frames
        w, h = panel_size
        n = len(self.motions)
        dpi = 100
        self.figure = Figure(figsize=(w * n / dpi, h / dpi), dpi=dpi, facecolor="white")
        self.canvas = FigureCanvasAgg(self.figure)
        self.axes, self.figures, self.grids = [], [], []
        for k, m in enumerate(self.motions):
            ax = self.figure.add_axes((k / n, 0.0, 1.0 / n, 0.92))
            height = max(1.0, float(np.ptp(self.positions[k][0, :, 1])))
            lo, hi = self.floors[k] - 0.3 * height, self.floors[k] + 1.15 * height
            half = 0.5 * (hi - lo) * w / (0.92 * h)  # equal scale on both screen axes
            ax.set_xlim(-half, half)
            ax.set_ylim(lo, hi)
            ax.axis("off")
            self.figure.text((k + 0.5) / n, 0.95, self.titles[k], ha="center", va="center",
                             fontsize=10)
            sides = joint_sides(m.skeleton)
            colors = [SIDE_COLORS[sides[j]] for _, j in self.bones[k]]
            grid = LineCollection([], colors="#bbbbbb", linewidths=0.8, animated=True)
            fig = LineCollection([], colors=colors, linewidths=2.5, capstyle="round",
                                 animated=True)
            ax.add_collection(grid)
            ax.add_collection(fig)
            self.axes.append(ax)
            self.grids.append(grid)
            self.figures.append(fig)
        self.clock = self.figure.text(0.01, 0.02, "", fontsize=8, color="#666666",
                                      animated=True)
        self.canvas.draw()
        self.background = self.canvas.copy_from_bbox(self.figure.bbox)

    def _grid(self, center: np.ndarray, floor: float, azimuth: float) -> np.ndarray:
        """Floor grid lines (N, 2, 2) on screen around ``center`` (3,), scrolling with it."""
        lines = []
        for axis in (0, 2):
            other = 2 - axis
            start = np.floor((center[axis] - GRID_HALF) / GRID_STEP) * GRID_STEP
            for v in np.arange(start, center[axis] + GRID_HALF + 1e-9, GRID_STEP):
                a = np.zeros((2, 3))
                a[:, axis] = v
                a[:, other] = center[other] + np.array([-GRID_HALF, GRID_HALF])
                a[:, 1] = floor
                lines.append(a)
        pts = np.array(lines) - np.array([center[0], 0.0, center[2]])
        return project(pts, azimuth, self.elevation)

    def frame(self, t: int) -> np.ndarray:
        """RGB image (H, W, 3) uint8 of frame ``t`` of the first motion."""
        self.canvas.restore_region(self.background)
        time_s = t / self.fps
        for k, m in enumerate(self.motions):
            f = min(max(round(time_s * m.fps), 0), m.num_frames - 1)
            pos = self.positions[k][f]
            center = np.array([pos[0, 0], 0.0, pos[0, 2]])
            az = self.azimuths[k][f]
            screen = project(pos - center, az, self.elevation)
            self.grids[k].set_segments(self._grid(center, self.floors[k], az))
            self.figures[k].set_segments(screen[self.bones[k]])
            self.axes[k].draw_artist(self.grids[k])
            self.axes[k].draw_artist(self.figures[k])
        self.clock.set_text(f"{time_s:6.2f} s")
        self.figure.draw_artist(self.clock)
        return np.asarray(self.canvas.buffer_rgba())[..., :3].copy()

    def iter_frames(self, step: int = 1, start: int = 0, stop: int | None = None,
                    progress: bool = False) -> Iterator[np.ndarray]:
        """Frames ``start:stop:step`` one at a time, each (H, W, 3) uint8 (a long recording's
        frames do not fit in memory together: 10 min at 30 fps is 7 GB)."""
        idx = range(start, self.num_frames if stop is None else min(stop, self.num_frames), step)
        for t in tqdm(idx, desc="rendering", unit="frame", disable=not progress, leave=False):
            yield self.frame(t)

    def frames(self, step: int = 1, start: int = 0, stop: int | None = None,
               progress: bool = False) -> np.ndarray:
        """Frames ``start:stop:step`` as an array (N, H, W, 3) uint8."""
        return np.stack(list(self.iter_frames(step, start, stop, progress)))


def write_video(frames: np.ndarray | Iterable[np.ndarray], path: str | Path, fps: float,
                overwrite: bool = False) -> Path:
    """Write RGB frames (N, H, W, 3) uint8 (or an iterable of (H, W, 3) frames, streamed to
    the encoder) as ``.mp4`` (H.264) or ``.gif`` (one palette of ``GIF_COLORS`` colours for
    the whole clip), both encoded by the ffmpeg binary that the imageio-ffmpeg package ships
    (no system ffmpeg needed).

    Refuses to replace an existing file unless ``overwrite``.
    """
    import imageio_ffmpeg  # the [viz] extra's

    path = Path(path)
    check_output(path, overwrite)
    suffix = path.suffix.lower()
    if isinstance(frames, np.ndarray) and (
            frames.ndim != 4 or frames.shape[-1] != 3 or len(frames) == 0):
        raise ValueError(f"write_video: expected frames (N, H, W, 3), got {frames.shape}")
    frames = iter(frames)
    first = np.asarray(next(frames, np.zeros((0,))), dtype=np.uint8)
    if first.ndim != 3 or first.shape[-1] != 3:
        raise ValueError(f"write_video: expected frames (H, W, 3), got {first.shape}")
    h, w = first.shape[:2]
    if suffix == ".mp4":
        if h % 2 or w % 2:
            raise ValueError(f"write_video: H.264 needs even frame sizes, got {w}x{h}")
        options = {"codec": "libx264", "pix_fmt_out": "yuv420p", "quality": 7}
    elif suffix == ".gif":
        # ffmpeg's palettegen/paletteuse: one palette for the clip, several times faster than
        # Pillow's per-frame quantization
        # whole frames, no transparency: decoders that do not composite frames (imageio,
        # some viewers) show them right too
        graph = (f"split[a][b];[a]palettegen=max_colors={GIF_COLORS}:reserve_transparent=0[p];"
                 "[b][p]paletteuse=dither=none")
        options = {"codec": "gif", "pix_fmt_out": "pal8", "quality": None,
                   "output_params": ["-filter_complex", graph, "-gifflags", "-transdiff",
                                     "-loop", "0"]}
    else:
        raise ValueError(f"{path}: video format must be .mp4 or .gif, got {suffix!r}")
    with atomic_path(path) as tmp:  # an interrupted encoding leaves no truncated video
        writer = imageio_ffmpeg.write_frames(str(tmp), (w, h), fps=fps, macro_block_size=1,
                                             ffmpeg_log_level="error", **options)
        writer.send(None)  # start the ffmpeg process
        try:
            writer.send(np.ascontiguousarray(first))
            for f in frames:
                writer.send(np.ascontiguousarray(f, dtype=np.uint8))
        finally:
            writer.close()
    return path


def render_video(motions: Sequence[Motion], path: str | Path, titles: Sequence[str] | None = None,
                 fps: float | None = None, overwrite: bool = False, progress: bool = False,
                 max_seconds: float | None = None) -> Path:
    """Render ``motions`` side by side (see :class:`StickRenderer`) into an MP4 or GIF.

    fps : output frame rate; frames of the first motion are skipped to approach it (GIFs play
        poorly above ~20 fps; default: 15 for GIF, the motion's rate for MP4).
    max_seconds : only the first seconds of the motions.
    """
    path = Path(path)
    check_output(path, overwrite)
    renderer = StickRenderer(motions, titles)
    if fps is None:
        fps = 15.0 if path.suffix.lower() == ".gif" else renderer.fps
    step = max(1, round(renderer.fps / fps))
    stop = None if max_seconds is None else int(max_seconds * renderer.fps) + 1
    frames = renderer.iter_frames(step, stop=stop, progress=progress)
    return write_video(frames, path, renderer.fps / step, overwrite=overwrite)


def frame_strip(motions: Sequence[Motion], times: Sequence[float], path: str | Path,
                titles: Sequence[str] | None = None, columns: int = 4,
                overwrite: bool = False) -> Path:
    """A PNG with the panels of :class:`StickRenderer` at ``times`` (seconds), ``columns``
    images per row, for looking at a few frames at once."""
    import imageio.v3 as iio  # the [viz] extra's

    path = Path(path)
    check_output(path, overwrite)
    renderer = StickRenderer(motions, titles)
    images = [renderer.frame(round(t * renderer.fps)) for t in times]
    blank = np.full_like(images[0], 255)
    images += [blank] * (-len(images) % columns)
    rows = [np.concatenate(images[i:i + columns], axis=1) for i in range(0, len(images), columns)]
    with atomic_path(path) as tmp:
        iio.imwrite(tmp, np.concatenate(rows, axis=0))
    return path
