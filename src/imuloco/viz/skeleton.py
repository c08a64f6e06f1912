"""Stick-figure animations: side by side panels (ground truth, reconstruction), GIF and MP4.

Each panel follows its own figure (the pelvis stays in the middle, the floor grid scrolls under
it), seen by an orthographic camera from ``azimuth`` about the vertical and ``elevation`` above
the horizon; feet on the floor are marked. Under the panels a legend says which colour is what
and, when a method predicted its error, a strip shows that error over the rendered window with
a cursor at the current frame. Frames are drawn with matplotlib (Agg, so no display is needed,
blitting only what moves) and streamed one at a time to the ffmpeg binary that imageio-ffmpeg
ships (MP4: H.264; GIF: one palette for the clip), so memory does not grow with the clip.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable, Iterator, Sequence
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Self

import numpy as np
from tqdm.auto import tqdm

from imuloco.core.contacts import foot_contacts
from imuloco.core.motion import Motion
from imuloco.core.skeleton import Skeleton
from imuloco.errors import InputError
from imuloco.io.atomic import atomic_path, check_output
from imuloco.ops.filters import gaussian_smooth
from imuloco.ops.heading import heading_from_hips

log = logging.getLogger(__name__)

SIDE_COLORS = {"left": "#1f77b4", "right": "#d62728", "center": "#444444"}
SIDE_LABELS = {"left": "left side", "right": "right side", "center": "midline"}
CONTACT_COLOR = "#ff7f0e"  # a foot part on the floor
ERROR_COLOR = "#6a3d9a"  # the predicted error's line in the strip
UNRELIABLE_COLOR = "#f4c2c2"  # frames the method flags as unreliable, shaded in the strip
PANEL_SIZE = (320, 384)  # pixels (width, height); multiples of 16 keep H.264 from rescaling
LEGEND_PX = 18  # pixels of the legend's row under the panels
STRIP_PX = 52  # pixels of the predicted-error strip under the legend (its tick labels included)
GRID_STEP = 0.5  # metres between floor grid lines
GRID_HALF = 3.0  # metres of floor drawn around the pelvis
GIF_COLORS = 32  # palette size: a stick figure on white needs few colours
GIF_FPS = 15.0  # GIFs play poorly faster (browsers slow them down)
GIF_MAX_SECONDS = 30.0  # a GIF is a preview: ffmpeg holds its frames until the palette is made


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


def camera_axes(azimuth: float | np.ndarray, elevation: float
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Screen right, screen up and towards-the-camera unit vectors, each shape
    ``(*np.shape(azimuth), 3)``, of an orthographic camera at ``azimuth`` radians about +Y (0: on
    +Z looking towards -Z; one camera per value) and ``elevation`` radians above the horizon."""
    a = np.asarray(azimuth, dtype=np.float64)
    zero = np.zeros_like(a)
    right = np.stack([np.cos(a), zero, -np.sin(a)], axis=-1)
    back = np.stack([np.sin(a), zero, np.cos(a)], axis=-1)
    up = np.array([0.0, 1.0, 0.0])
    to_camera = np.cos(elevation) * back + np.sin(elevation) * up
    screen_up = -np.sin(elevation) * back + np.cos(elevation) * up
    return right, screen_up, to_camera


def project(points: np.ndarray, azimuth: float | np.ndarray, elevation: float) -> np.ndarray:
    """Orthographic projection of world points (Y up).

    Parameters
    ----------
    points : ndarray, shape (*A, ..., 3), metres.
    azimuth : float, or ndarray of shape A (the points' leading axes): one camera each.
    elevation : radians, see :func:`camera_axes`.

    Returns
    -------
    ndarray, shape (*A, ..., 2): screen x (right) and y (up), metres.
    """
    right, up, _ = camera_axes(azimuth, elevation)
    points = np.asarray(points, dtype=np.float64)
    trailing = (1,) * (points.ndim - right.ndim)  # the points' axes after A
    right = right.reshape(right.shape[:-1] + trailing + (3,))
    up = up.reshape(up.shape[:-1] + trailing + (3,))
    return np.stack([(points * right).sum(axis=-1), (points * up).sum(axis=-1)], axis=-1)


def follow_azimuth(motion: Motion, offset_deg: float = 30.0, sigma_s: float = 1.0,
                   positions: np.ndarray | None = None) -> np.ndarray:
    """Per-frame camera azimuth (T,) that keeps seeing the figure from its left side, turned
    ``offset_deg`` towards its front, as it turns: the hip-line heading, unwrapped and
    smoothed over ``sigma_s`` seconds (so the camera does not sway with the pelvis).
    ``positions`` (T, J, 3): the motion's joint positions when already computed."""
    if positions is None:
        positions = motion.positions()
    sk = motion.skeleton
    pos = positions[:, [sk.part("left_hip"), sk.part("right_hip")]]
    theta = np.unwrap(heading_from_hips(pos[:, 0], pos[:, 1]))
    if motion.num_frames > 1:
        theta = gaussian_smooth(theta, sigma_s * motion.fps)
    return theta + np.pi / 2 - np.radians(offset_deg)


def _bones(skeleton: Skeleton) -> np.ndarray:
    """(B, 2) parent-child joint index pairs."""
    return np.array([(int(p), j) for j, p in enumerate(skeleton.parents) if p >= 0],
                    dtype=int).reshape(-1, 2)


FOOT_PARTS = ("left_ankle", "right_ankle", "left_toe", "right_toe")
CLOCK_CHARS = "0123456789.- s"


def _foot_contacts(motion: Motion) -> tuple[np.ndarray, np.ndarray] | None:
    """The joints (4,) of :data:`FOOT_PARTS` and whether each is on the floor, (T, 4) bool
    (heel contact at the ankle, toe contact at the toe: :func:`foot_contacts`); None when the
    skeleton does not map both legs or the motion has a single frame."""
    body = motion.skeleton.body_map or {}
    if motion.num_frames < 2 or not all(p in body for p in (*FOOT_PARTS, "right_hip")):
        return None
    if motion.skeleton.leg_length() <= 0:
        return None
    c = foot_contacts(motion)
    joints = np.array([motion.skeleton.part(p) for p in FOOT_PARTS])
    return joints, np.stack([c["left_heel"], c["right_heel"], c["left_toe"], c["right_toe"]],
                            axis=1)


CHUNK_FRAMES = 64  # frames whose pixel geometry is computed at once: numpy's per-call cost,
# paid for each frame, took a third of a frame's drawing


def _grid(centers: np.ndarray, floor: float) -> np.ndarray:
    """Floor grid lines (n, L, 2, 3), world metres relative to each frame's ``centers``
    (n, 3) (the pelvis over the floor), every :data:`GRID_STEP` within :data:`GRID_HALF` of it
    along X and Z, at height ``floor``: the grid scrolls under the figure."""
    count = round(2 * GRID_HALF / GRID_STEP) + 1  # lines per direction (the first at or
    # below centre - GRID_HALF, so the last at or below centre + GRID_HALF)
    lines = []
    for axis in (0, 2):
        other = 2 - axis
        start = np.floor((centers[:, axis] - GRID_HALF) / GRID_STEP) * GRID_STEP
        a = np.empty((len(centers), count, 2, 3))
        a[..., axis] = (start[:, None] + GRID_STEP * np.arange(count))[..., None]
        a[..., other] = centers[:, other, None, None] + np.array([-GRID_HALF, GRID_HALF])
        a[..., 1] = floor
        lines.append(a)
    return np.concatenate(lines, axis=1) - centers[:, None, None]


@dataclass(frozen=True)
class _Geometry:
    """What moves in a panel over frames ``first`` to ``first + n``, in pixels: the floor grid
    (n, L, 2, 2), each side's bones (n, 2 B, 2) in :attr:`StickRenderer._limb_gcs`'s order and
    the foot joints (n, 4, 2) of :data:`FOOT_PARTS` (None: feet not marked)."""

    first: int
    grid: np.ndarray
    limbs: list[np.ndarray]
    feet: np.ndarray | None


class StickRenderer:
    """Draws frames of one or more motions side by side into RGB arrays.

    What moves (floor grid, bones, feet on the floor, the strip's cursor) is drawn each frame
    over a saved background by the Agg renderer's own ``draw_path`` with graphics contexts
    prepared once, and the clock is stamped from glyphs drawn once: matplotlib's artists
    redo their layout, transforms and text shaping on every draw, which took most of a
    frame's time (a 10-minute walk took minutes to render).

    Parameters
    ----------
    motions : motions on any skeletons, drawn left to right (all frames are drawn at the
        times of the first: each motion's frame ``round(t * fps)``, clamped).
    titles : one caption per panel.
    azimuth, elevation : camera in radians (azimuth ``None``: each panel's camera follows its
        figure's heading, :func:`follow_azimuth`; elevation 0.25 rad).
    panel_size : (width, height) pixels per panel (the legend and strip are inside it).
    legend : a row under the panels saying which colour is what.
    error_m, unreliable : per motion (or None), its predicted error per frame (T,) in metres
        and its unreliable frames (T,) bool; the first motion with either gets the strip
        under the legend (its error over ``window``, unreliable frames shaded, a cursor at
        the current frame).
    window : (start, end) seconds that the strip spans (default: the first motion's length).
    """

    def __init__(self, motions: Sequence[Motion], titles: Sequence[str] | None = None,
                 azimuth: float | None = None, elevation: float = 0.25,
                 panel_size: tuple[int, int] = PANEL_SIZE, legend: bool = True,
                 error_m: Sequence[np.ndarray | None] | None = None,
                 unreliable: Sequence[np.ndarray | None] | None = None,
                 window: tuple[float, float] | None = None) -> None:
        import matplotlib  # the [viz] extra's

        matplotlib.use("Agg")
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        if not motions:
            raise ValueError("StickRenderer: no motion to draw")
        self.motions = list(motions)
        n = len(self.motions)
        self.titles = list(titles) if titles is not None else [m.name for m in self.motions]
        self.elevation = elevation
        self.positions = [m.positions() for m in self.motions]
        self.azimuths = [follow_azimuth(m, positions=p) if azimuth is None
                         else np.full(m.num_frames, azimuth)
                         for m, p in zip(self.motions, self.positions)]
        self.bones = [_bones(m.skeleton) for m in self.motions]
        self.floors = [float(np.percentile(p[:, :, 1].min(axis=1), 5)) for p in self.positions]
        self.contacts = [_foot_contacts(m) for m in self.motions]
        self.fps = self.motions[0].fps
        self.num_frames = self.motions[0].num_frames
        errs = list(error_m) if error_m is not None else [None] * n
        flags = list(unreliable) if unreliable is not None else [None] * n
        strip = next((k for k in range(n) if errs[k] is not None or flags[k] is not None), None)

        w, h = panel_size
        dpi = 100
        self.figure = Figure(figsize=(w * n / dpi, h / dpi), dpi=dpi, facecolor="white")
        self.canvas = FigureCanvasAgg(self.figure)
        self.size = self.canvas.get_width_height()  # (W, H) pixels of a frame
        strip_px = STRIP_PX if strip is not None else 0
        bottom = (strip_px + (LEGEND_PX if legend else 0)) / h  # the panels start above
        self.axes = []
        for k in range(n):
            ax = self.figure.add_axes((k / n, bottom, 1.0 / n, 0.92 - bottom))
            height = max(1.0, float(np.ptp(self.positions[k][0, :, 1])))
            lo, hi = self.floors[k] - 0.3 * height, self.floors[k] + 1.15 * height
            half = 0.5 * (hi - lo) * w / ((0.92 - bottom) * h)  # equal scale on screen
            ax.set_xlim(-half, half)
            ax.set_ylim(lo, hi)
            ax.axis("off")
            self.figure.text((k + 0.5) / n, 0.95, self.titles[k], ha="center", va="center",
                             fontsize=10)
            self.axes.append(ax)
        self.sides = [np.array(joint_sides(m.skeleton))[b[:, 1]]  # each bone's child's side
                      for m, b in zip(self.motions, self.bones)]
        if legend:
            self._legend(strip_px / h, LEGEND_PX / h)
        self.strip = None
        if strip is not None:
            if window is None:
                window = (0.0, self.motions[0].duration)
            self.strip = self._strip(self.motions[strip], errs[strip], flags[strip], window,
                                     strip_px, n > 1 and self.titles[strip])
        self.canvas.draw()
        self.background = self.canvas.copy_from_bbox(self.figure.bbox)
        self._prepare_drawing()
        clock_chars = len(f"{self.motions[0].duration:.2f}") + 2
        self._glyphs = self._clock_glyphs(0.01 / n, 0.95, clock_chars)

    def _legend(self, bottom: float, height: float) -> None:
        """The colours' legend, centred in the figure's row ``bottom`` to ``bottom + height``
        (figure fractions): the sides' colours and, when feet are marked, the contact."""
        from matplotlib.lines import Line2D  # the [viz] extra's

        drawn = {s for sides in self.sides for s in sides}
        handles = [Line2D([], [], color=c, lw=2.5) for s, c in SIDE_COLORS.items()
                   if s in drawn]
        labels = [SIDE_LABELS[s] for s in SIDE_COLORS if s in drawn]
        if any(c is not None for c in self.contacts):
            handles.append(Line2D([], [], ls="none", marker="o", ms=4.5, color=CONTACT_COLOR))
            labels.append("foot on the floor")
        if not handles:  # a skeleton without bones
            return
        self.figure.legend(handles, labels, loc="center", ncol=len(handles), fontsize=7,
                           frameon=False, handlelength=1.4, handletextpad=0.4,
                           columnspacing=1.0, borderaxespad=0.0,
                           bbox_to_anchor=(0.5, bottom + height / 2))

    def _strip(self, motion: Motion, error_m: np.ndarray | None,
               unreliable: np.ndarray | None, window: tuple[float, float], strip_px: int,
               title: str | bool):
        """The predicted-error strip at the figure's bottom (``strip_px`` high): ``error_m``
        in cm over ``window`` seconds, ``unreliable`` frames shaded; returns its axes."""
        w, h = self.size
        ax = self.figure.add_axes((34 / w, 12 / h, 1 - 42 / w, (strip_px - 26) / h))
        t = motion.times
        start, end = window
        end = max(end, start + 1 / motion.fps)  # one frame: a span all the same
        inside = (t >= start - 1 / motion.fps) & (t <= end + 1 / motion.fps)
        label = "predicted error, cm"
        top = 1.0
        if error_m is not None and np.isfinite(error_m[inside]).any():
            cm = 100 * np.asarray(error_m, dtype=np.float64)
            top = float(np.nanmax(cm[inside])) * 1.1
            ax.plot(t[inside], cm[inside], color=ERROR_COLOR, lw=0.9)
        elif error_m is None:
            label = "frames the method flags"
        if unreliable is not None and np.any(unreliable[inside]):
            ax.fill_between(t[inside], 0, 1, where=np.asarray(unreliable, bool)[inside],
                            step="mid", color=UNRELIABLE_COLOR, lw=0,
                            transform=ax.get_xaxis_transform())
            label += "; shaded: unreliable frames"
        if isinstance(title, str):
            label = f"{title}: {label}"
        ax.set_xlim(start, end)
        ax.set_ylim(0, top)
        ax.set_yticks([0, round(top / 1.1)] if top > 2 else [0])
        ax.tick_params(labelsize=6, length=2, pad=1)
        for side in ("top", "right"):
            ax.spines[side].set_visible(False)
        ax.text(0.0, 1.04, label, transform=ax.transAxes, fontsize=6, va="bottom",
                color="#333333")
        return ax

    def _prepare_drawing(self) -> None:
        """Graphics contexts and data-to-pixel transforms for what moves (the axes' limits
        are fixed, so each transform is one affine map)."""
        from matplotlib.colors import to_rgba  # the [viz] extra's
        from matplotlib.path import Path as MplPath
        from matplotlib.transforms import Affine2D, IdentityTransform

        self._renderer = self.canvas.get_renderer()
        self._identity = IdentityTransform()
        self._mpl_path = MplPath
        self._codes: dict[int, np.ndarray] = {}  # MOVETO, LINETO per segment, by count
        self._chunks: dict[int, _Geometry] = {}  # per panel, the frames being drawn

        def gc(ax, color: str, width: float):
            g = self._renderer.new_gc()
            g.set_foreground(color)
            g.set_linewidth(width)
            g.set_capstyle("round")
            g.set_joinstyle("round")
            g.set_antialiased(True)
            g.set_clip_rectangle(ax.bbox)
            return g

        self._to_pixels = [ax.transData.frozen() for ax in self.axes]
        self._grid_gc = [gc(ax, "#bbbbbb", 0.8) for ax in self.axes]
        self._limb_gcs = [[(np.flatnonzero(sides == s), gc(ax, c, 2.5))
                           for s, c in SIDE_COLORS.items() if s in sides]
                          for ax, sides in zip(self.axes, self.sides)]
        self._foot_gc = [gc(ax, CONTACT_COLOR, 0.5) for ax in self.axes]
        self._dot = MplPath.unit_circle()
        self._dot_size = Affine2D().scale(self._renderer.points_to_pixels(4.5) / 2)
        self._dot_face = to_rgba(CONTACT_COLOR)
        if self.strip is not None:
            self._cursor_gc = gc(self.strip, "#111111", 1.0)
            self._strip_to_pixels = self.strip.transData.frozen()
            y0, y1 = self.strip.bbox.y0, self.strip.bbox.y1
            self._cursor_y = (y0, y1)

    def _clock_glyphs(self, x: float, y: float, chars: int) -> tuple:
        """The clock's place (row, column slices of the frame) and its characters' images
        (one each, drawn once on the title row's plain background, which nothing moving
        covers): matplotlib would shape the clock's text again on every frame."""
        text = self.figure.text(x, y, "0" * chars, fontsize=8, color="#666666",
                                family="DejaVu Sans Mono", va="center")
        box = text.get_window_extent(self._renderer)
        _, height = self.size
        rows = slice(max(0, int(height - box.y1) - 1), int(np.ceil(height - box.y0)) + 1)
        advance = box.width / chars
        x0 = int(box.x0)
        width = int(np.ceil(advance)) + 2
        glyphs = {}
        pixels = np.asarray(self.canvas.buffer_rgba())
        for c in CLOCK_CHARS:
            self.canvas.restore_region(self.background)
            pixels[rows, x0:x0 + width] = 255  # on white, whatever a long title put there
            text.set_text(c)
            self.figure.draw_artist(text)
            glyphs[c] = pixels[rows, x0:x0 + width].copy()
        text.remove()
        columns = [x0 + round(i * advance) for i in range(chars)]
        return rows, columns, width, glyphs

    def _stamp_clock(self, image: np.ndarray, time_s: float) -> None:
        """Write ``time_s`` into the clock of ``image`` (H, W, 4) (dark glyphs on white: the
        darker pixel wins, so neighbouring glyphs' margins overlap harmlessly)."""
        rows, columns, width, glyphs = self._glyphs
        text = f"{time_s:{len(columns) - 2}.2f} s"[:len(columns)]
        for x, c in zip(columns, text):
            if c != " ":
                cell = image[rows, x:x + width]
                np.minimum(cell, glyphs[c][:, :cell.shape[1]], out=cell)

    def _geometry(self, k: int, f: int) -> _Geometry:
        """Pixel geometry of motion ``k``'s frames ``f`` to ``f + CHUNK_FRAMES`` (cached: the
        frames are drawn in order)."""
        g = self._chunks.get(k)
        if g is not None and g.first <= f < g.first + len(g.grid):
            return g
        m = self.motions[k]
        frames = slice(f, min(f + CHUNK_FRAMES, m.num_frames))
        pos = self.positions[k][frames]
        center = pos[:, 0] * [1.0, 0.0, 1.0]  # (n, 3): the pelvis over the floor
        az = self.azimuths[k][frames]
        to_pixels = self._to_pixels[k].transform

        def pixels(world: np.ndarray) -> np.ndarray:  # (n, ..., 3) -> (n, ..., 2)
            screen = project(world, az, self.elevation)
            return to_pixels(screen.reshape(-1, 2)).reshape(screen.shape)

        joints = pixels(pos - center[:, None])  # (n, J, 2)
        limbs = [joints[:, self.bones[k][bones]].reshape(len(joints), -1, 2)
                 for bones, _ in self._limb_gcs[k]]
        feet = None if self.contacts[k] is None else joints[:, self.contacts[k][0]]
        g = self._chunks[k] = _Geometry(f, pixels(_grid(center, self.floors[k])), limbs, feet)
        return g

    def _draw_segments(self, gc, verts: np.ndarray) -> None:
        """Draw segments, vertices (2 N, 2) in pixels (start, end, start, ...), as one path."""
        codes = self._codes.get(len(verts))
        if codes is None:
            codes = self._codes[len(verts)] = np.tile(
                np.array([self._mpl_path.MOVETO, self._mpl_path.LINETO], np.uint8),
                len(verts) // 2)
        self._renderer.draw_path(gc, self._mpl_path(verts, codes), self._identity)

    def frame(self, t: int) -> np.ndarray:
        """RGB image (H, W, 3) uint8 of frame ``t`` of the first motion."""
        return self.draw(t)[..., :3].copy()

    def draw(self, t: int) -> np.ndarray:
        """Draw frame ``t`` of the first motion; returns the canvas's RGBA pixels (H, W, 4)
        uint8 themselves (no copy: valid until the next draw)."""
        self.canvas.restore_region(self.background)
        time_s = t / self.fps
        for k, m in enumerate(self.motions):
            f = min(max(round(time_s * m.fps), 0), m.num_frames - 1)
            g = self._geometry(k, f)
            i = f - g.first
            self._draw_segments(self._grid_gc[k], g.grid[i].reshape(-1, 2))
            for verts, (_, gc) in zip(g.limbs, self._limb_gcs[k]):
                self._draw_segments(gc, verts[i])
            if g.feet is not None:
                down = self.contacts[k][1][f]
                if down.any():
                    self._renderer.draw_markers(self._foot_gc[k], self._dot, self._dot_size,
                                                self._mpl_path(g.feet[i][down]),
                                                self._identity, self._dot_face)
        if self.strip is not None:
            x = self._strip_to_pixels.transform([[time_s, 0.0]])[0, 0]
            y0, y1 = self._cursor_y
            self._draw_segments(self._cursor_gc, np.array([[x, y0], [x, y1]]))
        image = np.asarray(self.canvas.buffer_rgba())
        self._stamp_clock(image, time_s)
        return image

    def iter_frames(self, step: int = 1, start: int = 0, stop: int | None = None,
                    progress: bool = False) -> Iterator[np.ndarray]:
        """Frames ``start:stop:step`` one at a time, each (H, W, 3) uint8 (a long recording's
        frames do not fit in memory together: 10 min at 30 fps is 7 GB)."""
        idx = range(start, self.num_frames if stop is None else min(stop, self.num_frames), step)
        for t in tqdm(idx, desc="rendering", unit="frame", disable=not progress, leave=False):
            yield self.frame(t)

    def frames(self, step: int = 1, start: int = 0, stop: int | None = None,
               progress: bool = False) -> np.ndarray:
        """Frames ``start:stop:step`` as an array (N, H, W, 3) uint8 (a short clip's: for a
        video, stream :meth:`iter_frames` instead)."""
        return np.stack(list(self.iter_frames(step, start, stop, progress)))


class VideoWriter:
    """An ``.mp4`` (H.264) or ``.gif`` (one palette of ``GIF_COLORS`` colours for the clip)
    being encoded while its frames arrive: each frame (H, W, 3) uint8 given to :meth:`send`
    goes down a pipe to the ffmpeg binary that the imageio-ffmpeg package ships (no system
    ffmpeg needed) before :meth:`send` returns (the pipe blocks while ffmpeg is busy), so a
    writer holds no frame and the caller may reuse the array.

    A context manager: the file appears (atomically) when the block ends without error; an
    interrupted encoding leaves no truncated video. Refuses to replace an existing file unless
    ``overwrite``.

    Parameters
    ----------
    path : ``.mp4`` or ``.gif``.
    size : (width, height) pixels of every frame (even, for H.264).
    fps : frames per second of the video.
    channels : 3 (frames RGB) or 4 (RGBA, alpha ignored: a canvas's own pixels, no copy).
    """

    def __init__(self, path: str | Path, size: tuple[int, int], fps: float,
                 overwrite: bool = False, channels: int = 3) -> None:
        self.path = Path(path)
        check_output(self.path, overwrite)
        self.size = (int(size[0]), int(size[1]))
        self.fps = float(fps)
        if channels not in (3, 4):
            raise ValueError(f"write_video: channels must be 3 or 4, got {channels}")
        self.channels = channels
        self.frames = 0
        w, h = self.size
        suffix = self.path.suffix.lower()
        if suffix == ".mp4":
            if h % 2 or w % 2:
                raise ValueError(f"write_video: H.264 needs even frame sizes, got {w}x{h}")
            # x264's ultrafast preset with CABAC and B-frames back, at CRF 23: ffmpeg took 13
            # ms of CPU a frame at x264's default (medium, CRF 15), 3.3 at superfast, 2.2
            # so (RGBA in, YUV conversion included), for files 20 % larger than superfast's
            # (plain ultrafast: 60 %) that look the same on a stick figure on white (mean
            # absolute pixel difference to the drawn frames 1.06 of 255; docs/results/render)
            self.options = {"codec": "libx264", "pix_fmt_out": "yuv420p", "quality": None,
                            "output_params": ["-preset", "ultrafast", "-x264-params",
                                              "cabac=1:bframes=3", "-crf", "23"]}
        elif suffix == ".gif":
            # ffmpeg's palettegen/paletteuse: one palette for the clip, several times faster
            # than Pillow's per-frame quantization; whole frames, no transparency: decoders
            # that do not composite frames (imageio, some viewers) show them right too
            graph = (f"split[a][b];[a]palettegen=max_colors={GIF_COLORS}:"
                     "reserve_transparent=0[p];[b][p]paletteuse=dither=none")
            self.options = {"codec": "gif", "pix_fmt_out": "pal8", "quality": None,
                            "output_params": ["-filter_complex", graph, "-gifflags",
                                              "-transdiff", "-loop", "0"]}
        else:
            raise ValueError(f"{self.path}: video format must be .mp4 or .gif, got {suffix!r}")
        self._stack = ExitStack()

    def __enter__(self) -> Self:
        import imageio_ffmpeg  # the [viz] extra's

        with ExitStack() as stack:
            tmp = stack.enter_context(atomic_path(self.path))
            writer = imageio_ffmpeg.write_frames(
                str(tmp), self.size, fps=self.fps, macro_block_size=1,
                ffmpeg_log_level="error", pix_fmt_in="rgb24" if self.channels == 3 else "rgba",
                **self.options)
            writer.send(None)  # start the ffmpeg process
            stack.callback(writer.close)  # closed first: ffmpeg finishes the file, then renamed
            self._writer = writer
            self._stack = stack.pop_all()
        return self

    def send(self, frame: np.ndarray) -> None:
        """Encode one frame (H, W, channels) uint8 of the writer's size."""
        frame = np.ascontiguousarray(frame, dtype=np.uint8)
        shape = (self.size[1], self.size[0], self.channels)
        if frame.shape != shape:
            raise ValueError(f"write_video: expected frames {shape}, got {frame.shape}")
        self._writer.send(frame)
        self.frames += 1

    def close(self) -> None:
        """Finish the file before the block ends (nothing more to send); the block's end then
        does nothing more."""
        self._stack.close()

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None,
                 tb: TracebackType | None) -> bool:
        return bool(self._stack.__exit__(kind, value, tb))


def write_video(frames: np.ndarray | Iterable[np.ndarray], path: str | Path, fps: float,
                overwrite: bool = False) -> Path:
    """Write RGB frames (N, H, W, 3) uint8 (or an iterable of (H, W, 3) frames, streamed to
    the encoder one at a time) as ``.mp4`` or ``.gif`` (:class:`VideoWriter`).

    Refuses to replace an existing file unless ``overwrite``.
    """
    path = Path(path)
    check_output(path, overwrite)
    if isinstance(frames, np.ndarray) and (
            frames.ndim != 4 or frames.shape[-1] != 3 or len(frames) == 0):
        raise ValueError(f"write_video: expected frames (N, H, W, 3), got {frames.shape}")
    frames = iter(frames)
    first = np.asarray(next(frames, np.zeros((0,))), dtype=np.uint8)
    if first.ndim != 3 or first.shape[-1] != 3:
        raise ValueError(f"write_video: expected frames (H, W, 3), got {first.shape}")
    with VideoWriter(path, (first.shape[1], first.shape[0]), fps, overwrite) as out:
        out.send(first)
        for f in frames:
            out.send(f)
    return path


def frame_window(motion: Motion, start: float | None = None, end: float | None = None,
                 max_seconds: float | None = None) -> tuple[int, int]:
    """Frames ``first:stop`` of ``motion`` from ``start`` to ``end`` seconds, both included
    (None: the motion's first, last frame), at most ``max_seconds`` long (cut at the
    motion's end).

    Raises :class:`imuloco.errors.InputError` when ``start`` or ``end`` is outside the motion,
    ``start`` is not before ``end``, or no frame falls in the window.
    """
    duration, fps = motion.duration, motion.fps
    name = motion.name or "the motion"
    given = start is not None or end is not None
    first_s = 0.0 if start is None else float(start)
    if max_seconds is not None:
        cap = first_s + float(max_seconds)
        end = min(cap, duration) if end is None else min(float(end), cap)
    end_s = duration if end is None else float(end)
    if not (math.isfinite(first_s) and math.isfinite(end_s)):
        raise InputError(f"render window: start and end must be numbers of seconds, got "
                         f"{first_s} and {end_s}")
    span = f"{name} runs from 0 to {duration:.2f} s"
    if first_s < 0 or first_s > duration:
        raise InputError(f"render window: start {first_s:g} s is outside the motion ({span})")
    if end_s < 0 or end_s > duration + 0.5 / fps:
        raise InputError(f"render window: end {end_s:g} s is outside the motion ({span})")
    if given and first_s >= end_s:
        raise InputError(f"render window: start {first_s:g} s must come before end "
                         f"{end_s:g} s")
    first = math.ceil(first_s * fps - 1e-6)
    stop = min(motion.num_frames, math.floor(end_s * fps + 1e-6) + 1)
    if stop <= first:
        raise InputError(f"render window: no frame of {name} ({fps:g} fps) between "
                         f"{first_s:g} and {end_s:g} s")
    return first, stop


def video_step(path: str | Path, fps: float, rate: float | None = None) -> int:
    """Frames of a ``fps`` motion per frame of the video ``path``: about ``rate`` frames a
    second (None: :data:`GIF_FPS` for a GIF, every frame for an MP4)."""
    if rate is None:
        rate = GIF_FPS if Path(path).suffix.lower() == ".gif" else fps
    return max(1, round(fps / rate))


def render_videos(motions: Sequence[Motion], paths: Sequence[str | Path],
                  titles: Sequence[str] | None = None, start: float | None = None,
                  end: float | None = None, max_seconds: float | None = None,
                  rates: Sequence[float | None] | None = None,
                  error_m: Sequence[np.ndarray | None] | None = None,
                  unreliable: Sequence[np.ndarray | None] | None = None,
                  overwrite: bool = False, progress: bool = False,
                  gif_max_seconds: float | None = GIF_MAX_SECONDS) -> list[Path]:
    """Render ``motions`` side by side (:class:`StickRenderer`) into MP4s and GIFs at once.

    Each frame of the window (:func:`frame_window`: ``start`` to ``end`` seconds, at most
    ``max_seconds``) is drawn once and sent to every video that shows it, then dropped: memory
    holds one frame whatever the window's length. The progress bar counts frames the encoders
    took. ``rates``: frames per second per video (None: :func:`video_step`'s default). A GIF
    shows at most ``gif_max_seconds`` from the window's start (None: no cap; ffmpeg holds a
    GIF's frames until it has its palette); a cut is logged as a warning. ``error_m`` and
    ``unreliable`` (per motion) fill the predicted-error strip.
    """
    paths = [Path(p) for p in paths]
    for p in paths:
        check_output(p, overwrite)
    fps = motions[0].fps
    first, stop = frame_window(motions[0], start, end, max_seconds)
    rates = list(rates) if rates is not None else [None] * len(paths)
    plans = []
    for path, rate in zip(paths, rates):
        last = stop
        if path.suffix.lower() == ".gif" and gif_max_seconds is not None:
            last = min(stop, first + max(1, round(gif_max_seconds * fps)))
            if last < stop:
                log.warning("%s: a GIF shows at most %g s: %.1f to %.1f s of the %.1f to "
                            "%.1f s asked (an MP4 has no such cap; render another window for "
                            "the rest)", path.name, gif_max_seconds, first / fps, last / fps,
                            first / fps, (stop - 1) / fps)
        plans.append(range(first, last, video_step(path, fps, rate)))
    last = max(r.stop for r in plans)
    renderer = StickRenderer(motions, titles, error_m=error_m, unreliable=unreliable,
                             window=(first / fps, (last - 1) / fps))
    def wanted() -> Iterator[int]:
        return (t for t in range(first, last) if any(t in r for r in plans))

    with ExitStack() as stack:
        bar = stack.enter_context(tqdm(total=sum(1 for _ in wanted()), desc="encoding",
                                       unit="frame", disable=not progress, leave=False))
        writers = [stack.enter_context(VideoWriter(p, renderer.size, fps / r.step, overwrite,
                                                   channels=4))
                   for p, r in zip(paths, plans)]
        for t in wanted():
            image = renderer.draw(t)  # the canvas itself: sent before the next draw
            for writer, r in zip(writers, plans):
                if t in r:
                    writer.send(image)
                    if t == r[-1]:  # a GIF's ffmpeg lets go of the frames it held
                        writer.close()
            bar.update()
        bar.set_postfix_str("finishing " + ", ".join(p.name for p in paths))
    return paths


def render_video(motions: Sequence[Motion], path: str | Path, titles: Sequence[str] | None = None,
                 fps: float | None = None, overwrite: bool = False, progress: bool = False,
                 max_seconds: float | None = None, start: float | None = None,
                 end: float | None = None, error_m: Sequence[np.ndarray | None] | None = None,
                 unreliable: Sequence[np.ndarray | None] | None = None) -> Path:
    """Render ``motions`` side by side into one MP4 or GIF (:func:`render_videos`).

    fps : output frame rate; frames of the first motion are skipped to approach it (default:
        15 for GIF, the motion's rate for MP4).
    start, end : the window, seconds (default: the whole motion).
    max_seconds : at most this many seconds from ``start``.
    """
    return render_videos(motions, [path], titles, start, end, max_seconds, [fps], error_m,
                         unreliable, overwrite, progress)[0]


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
