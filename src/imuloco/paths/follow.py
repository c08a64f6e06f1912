"""The animation obeys the path (issue 40): a reconstruction's root and footfalls moved onto a
:class:`imuloco.paths.base.BodyPath`, the learned pose kept.

The rule (:func:`follow`):

- where the path knows its heading (``heading_rad`` not None: foot ZUPT, shank pivot, lower-back
  steps, the truth), the root's horizontal position is the path's ``root_xy`` at each frame,
  carried into the motion's world frame (origin the motion's first root position, x axis its
  initial heading), and the whole body is turned about the vertical, frame by frame, so that
  its heading follows the path's (:func:`turn_to_path`: a reconstruction
  whose heading drifts, 34 degrees over a 45 s walk for ``learned``, otherwise walked
  sideways along the path, its planted feet sliding, and lost its footfalls). The heading is
  of the path's kind (:func:`motion_heading`): the hips' facing for a ``"facing"`` path (the
  truth's), the direction of travel for a ``"travel"`` one (the sensor estimators'), whose
  body keeps the motion's own facing against its travel: walking backwards or side-stepping,
  the animation walks backwards or sideways along the path, as the learned pose does, rather
  than forwards (bandai-namco-1's walk-back with the truth's pose and the shank's path: the
  root travelled 176 degrees off the truth's);
- where it knows only distances (stride lengths: shank pivot, lower-back steps), the motion
  keeps its own direction and each stride's horizontal root displacement is rescaled so that
  its length is the path's (one gain per stride of the foot with the most strides: the path's
  root displacement over the stride's time, whose length the estimators take from the stride
  lengths, over the motion's; frames outside every stride take the nearest stride's gain);
- the root's height and every joint rotation above the hips are the motion's: the pose
  relative to the root is unchanged but for the legs, which bend (two-bone IK,
  :func:`imuloco.methods.postprocess.lock_feet`) only to keep a planted foot where it landed
  once the root has moved (contacts detected on the moved motion,
  :func:`imuloco.phases.contacts.foot_contacts`).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.ndimage import median_filter

from imuloco.core.motion import Motion
from imuloco.core.recording import Recording
from imuloco.methods.postprocess import lock_feet
from imuloco.ops.heading import wrap_angle
from imuloco.ops.rotations import about_y, qmul
from imuloco.paths.base import BodyPath, Stride, to_floor
from imuloco.paths.geometry import MIN_WALK_SPEED, smooth_over
from imuloco.paths.registry import ESTIMATORS, estimate_path
from imuloco.paths.truth import facing, path_of_motion
from imuloco.phases.contacts import FEET, foot_contacts

MAX_GAIN = 4.0  # a stride's gain is clipped to [1/MAX_GAIN, MAX_GAIN] (a still motion's stride)
TRAVEL_S = 1.0  # the motion's travel: its root averaged over about a stride (the sway out)
OFFSET_S = 2.0  # its travel against its facing: a running median over two strides


def motion_heading(motion: Motion, kind: str = "facing") -> np.ndarray:
    """``motion``'s heading (T,), radians about +Y (unwrapped), of a path's ``heading_kind``:
    ``"facing"``, the hips' (:func:`imuloco.paths.truth.facing`); ``"travel"``, its direction
    of travel: the facing plus the motion's own travel against it (the root averaged over
    TRAVEL_S, its direction minus the facing, a running median over OFFSET_S; held where the
    root moves slower than MIN_WALK_SPEED, 0 for a motion that never moves)."""
    f = facing(motion)
    if kind == "facing":
        return f
    if kind != "travel":
        raise ValueError(f"heading_kind must be 'facing' or 'travel', got {kind!r}")
    xz = smooth_over(motion.root[:, [2, 0]], motion.fps, TRAVEL_S)  # (Z, X): yaw from +Z
    v = np.gradient(xz, axis=0) * motion.fps if len(xz) > 1 else np.zeros_like(xz)
    moving = np.linalg.norm(v, axis=1) >= MIN_WALK_SPEED
    if not moving.any():
        return f
    offset = np.unwrap(wrap_angle(np.arctan2(v[:, 1], v[:, 0]) - f))
    held = np.where(moving, np.arange(len(f)), 0)
    np.maximum.accumulate(held, out=held)
    held[:int(np.argmax(moving))] = int(np.argmax(moving))
    offset = median_filter(offset[held], max(1, round(OFFSET_S * motion.fps)), mode="nearest")
    return f + offset


def floor_frame(motion: Motion, kind: str = "facing") -> tuple[np.ndarray, float]:
    """The origin (3,) and initial heading (radians, :func:`motion_heading` of ``kind``) of
    ``motion``'s floor frame; of kind ``"facing"`` as
    :func:`imuloco.paths.truth.path_of_motion` reads them."""
    return motion.root[0].copy(), float(motion_heading(motion, kind)[0])


def from_floor(xy: np.ndarray, origin: np.ndarray, heading0: float) -> np.ndarray:
    """Floor-frame points (..., 2) -> world (X, Z) (..., 2): the inverse of
    :func:`imuloco.paths.base.to_floor` (height left out)."""
    c, s = np.cos(heading0), np.sin(heading0)
    a, b = xy[..., 0], xy[..., 1]
    return np.stack([s * a + c * b + origin[0], c * a - s * b + origin[2]], axis=-1)


def stride_gains(own_xy: np.ndarray, times: np.ndarray, path: BodyPath) -> np.ndarray:
    """Per-step gains (T-1,) that scale each of ``path``'s strides' displacement in
    ``own_xy`` (T, 2) (sampled at ``times``) to the path's length (module docstring)."""
    gains = np.full(len(times) - 1, np.nan)
    feet = [s.foot for s in path.strides]
    if not feet:
        return np.ones(len(times) - 1)
    foot = max(set(feet), key=feet.count)
    pt = np.asarray(path.times_s, float)
    for s in (s for s in path.strides if s.foot == foot and np.isfinite(s.length_m)):
        a, b = np.searchsorted(times, [s.start_s, s.end_s])
        b = min(b, len(times) - 1)
        if b <= a:
            continue
        own = float(np.linalg.norm(own_xy[b] - own_xy[a]))
        ends = [np.interp([times[a], times[b]], pt, path.root_xy[:, k]) for k in range(2)]
        want = float(np.hypot(ends[0][1] - ends[0][0], ends[1][1] - ends[1][0]))
        gain = want / own if own > 1e-6 else 1.0
        gains[a:b] = np.clip(gain, 1 / MAX_GAIN, MAX_GAIN)
    known = np.flatnonzero(np.isfinite(gains))
    if not len(known):
        return np.ones(len(times) - 1)
    nearest = known[np.clip(np.searchsorted(known, np.arange(len(gains))), 0, len(known) - 1)]
    left = known[np.clip(np.searchsorted(known, np.arange(len(gains))) - 1, 0, len(known) - 1)]
    pick = np.where(np.abs(left - np.arange(len(gains))) < np.abs(nearest - np.arange(
        len(gains))), left, nearest)
    return gains[pick]


def turn_to_path(motion: Motion, path: BodyPath, heading0: float) -> Motion:
    """``motion`` turned about the vertical at each frame (its root rotation, hence the whole
    body about the root) so that its heading of ``path``'s kind (:func:`motion_heading`: its
    hips' facing, or its direction of travel) is ``path``'s ``heading_rad`` at that time (a
    floor-frame angle, of the floor frame whose x axis is the world yaw ``heading0``)."""
    want = np.interp(motion.times, np.asarray(path.times_s, float),
                     np.unwrap(np.asarray(path.heading_rad, float)))
    turn = about_y(want + heading0 - motion_heading(motion, path.heading_kind))
    rotations = motion.rotations.copy()
    rotations[:, 0] = qmul(turn, rotations[:, 0])
    return Motion(motion.skeleton, rotations, motion.root, motion.fps, motion.name)


def follow(motion: Motion, path: BodyPath, lock: bool = True,
           frame: tuple[np.ndarray, float] | None = None) -> Motion:
    """``motion`` with its root's horizontal trajectory on ``path`` and its planted feet held
    by leg IK (module docstring's rule). ``path``'s times are seconds from the motion's first
    frame. lock : bend the legs to hold planted feet (False: the root alone moves).
    frame : the floor frame's world origin and initial heading (:func:`floor_frame`) for a
    piece of a longer motion (None: ``motion``'s own, the path's start moved to its start)."""
    if motion.num_frames < 2 or len(path.times_s) < 2:
        return motion
    origin, heading0 = floor_frame(motion, path.heading_kind) if frame is None else frame
    times = motion.times
    if path.heading_rad is not None:
        pt = np.asarray(path.times_s, float)
        xy = np.stack([np.interp(times, pt, path.root_xy[:, k]) for k in range(2)], axis=-1)
        if frame is None:
            xy -= xy[0]  # the motion starts where it starts
        motion = turn_to_path(motion, path, heading0)
    else:
        own = to_floor(motion.root, origin, heading0)
        steps = np.diff(own, axis=0) * stride_gains(own, times, path)[:, None]
        xy = np.vstack([np.zeros(2), np.cumsum(steps, axis=0)])
    root = motion.root.copy()
    root[:, [0, 2]] = from_floor(xy, origin, heading0)
    moved = Motion(motion.skeleton, motion.rotations, root, motion.fps, motion.name)
    if not lock:
        return moved
    c = foot_contacts(moved)  # on the moved motion: its feet are still where the path is right
    heel = np.stack([c[f"{f}_heel"] for f in FEET], axis=1)
    toe = np.stack([c[f"{f}_toe"] for f in FEET], axis=1)
    return lock_feet(moved, heel, toe)


def animation_strides(followed: Motion, path: BodyPath) -> list[Stride]:
    """The animation's own strides at ``path``'s stride times: the distance its ankle of the
    stride's foot moved on the floor from the stride's first footfall to its last (contacts
    detected on a jittery reconstruction split strides; the path's footfall times do not)."""
    idx = np.clip(np.round(np.array([[s.start_s, s.end_s] for s in path.strides]).reshape(
        -1, 2) * followed.fps).astype(int), 0, followed.num_frames - 1)
    ankles = followed.part_positions([f"{f}_ankle" for f in FEET])[:, :, [0, 2]]
    out = []
    for s, (a, b) in zip(path.strides, idx):
        k = FEET.index(s.foot)
        length = float(np.linalg.norm(ankles[b, k] - ankles[a, k]))
        dur = s.end_s - s.start_s
        out.append(Stride(s.foot, s.start_s, s.end_s, length, length / dur if dur > 0
                          else float("nan"), s.confidence))
    return out


def path_report(path: BodyPath, followed: Motion | None = None,
                strides: list[Stride] | None = None, distance_m: float | None = None) -> dict:
    """The report's ``path``: the path that drove the root (``source``, ``note``,
    ``distance_m``, ``strides``, ``stride_length_m``), the animation's own (``animation``:
    ``distance_m`` its root's polyline, ``strides``, ``stride_length_m`` and ``stride_rows``
    its :func:`animation_strides`; of ``followed``, or given as ``strides`` and
    ``distance_m``) and ``stride_agreement_pct``: the animation's mean stride against the
    path's, per cent."""
    est = path.to_json()
    if followed is not None:
        strides = animation_strides(followed, path)
        distance_m = path_of_motion(followed).distance_m()
    rows = BodyPath(np.zeros(1), np.zeros((1, 2)), None, [], strides or [], "", "").to_json()
    anim = {"distance_m": round(float(distance_m or 0.0), 4), "strides": rows["strides"],
            "stride_length_m": rows["stride_length_m"], "stride_rows": rows["stride_rows"]}
    a, b = anim["stride_length_m"], est["stride_length_m"]
    return {"source": est["source"], "note": est["note"], "distance_m": est["distance_m"],
            "strides": est["strides"], "stride_length_m": b, "animation": anim,
            "stride_agreement_pct": round(100 * (a / b - 1), 2) if a and b else None,
            "track_xy": track_xy(path), "footfalls": est["footfalls"]}


TRACK_S = 0.5  # the report's track of the pelvis: one point every half second


def track_xy(path: BodyPath, every_s: float = TRACK_S) -> list[list[float]]:
    """The pelvis's floor track of ``path`` every ``every_s`` seconds (and its end), metres
    rounded to cm: what the report's path-from-above plot draws."""
    t = path.times_s
    if len(t) == 0:
        return []
    keep = np.unique(np.r_[np.searchsorted(t, np.arange(t[0], t[-1], every_s)), len(t) - 1])
    return [[round(float(x), 2), round(float(y), 2)] for x, y in path.root_xy[keep]]


class PieceFollower:
    """:func:`follow` for a recording reconstructed in pieces (``--piece-seconds``): call it
    on each piece in order. With a heading, every piece's root is on the path in the first
    piece's floor frame (as one piece's); without, each piece keeps its own direction and has
    its strides rescaled, its root carried on from where the previous followed piece ended;
    the animation's strides (:func:`animation_strides` of the
    strides wholly inside a piece) and distance add up for :func:`path_report`."""

    def __init__(self, path: BodyPath) -> None:
        self.path = path
        self.strides: list[Stride] = []
        self.distance_m = 0.0
        self._offset = np.zeros(3)
        self._frames = 0
        self._last: np.ndarray | None = None
        self._frame: tuple[np.ndarray, float] | None = None

    def __call__(self, piece: Motion) -> Motion:
        t0 = self._frames / piece.fps
        t1 = t0 + piece.duration
        shift = [dataclasses.replace(s, start_s=s.start_s - t0, end_s=s.end_s - t0)
                 for s in self.path.strides if s.end_s > t0 and s.start_s < t1]
        local = dataclasses.replace(self.path, times_s=self.path.times_s - t0, strides=shift)
        if self.path.heading_rad is not None:
            if self._frame is None:
                self._frame = floor_frame(piece, self.path.heading_kind)
            moved = follow(piece, local, frame=self._frame)
        else:
            root = piece.root.copy()
            root[:, [0, 2]] += self._offset[[0, 2]]
            moved = follow(Motion(piece.skeleton, piece.rotations, root, piece.fps,
                                  piece.name), local)
        inside = dataclasses.replace(local, strides=[s for s in shift if s.start_s >= 0
                                                     and s.end_s <= piece.duration])
        self.strides += [dataclasses.replace(s, start_s=s.start_s + t0, end_s=s.end_s + t0)
                         for s in animation_strides(moved, inside)]
        xz = moved.root[:, [0, 2]]
        if self._last is not None:
            xz = np.vstack([self._last, xz])
        self.distance_m += float(np.linalg.norm(np.diff(xz, axis=0), axis=1).sum())
        self._last = moved.root[-1, [0, 2]].copy()
        self._offset[[0, 2]] = moved.root[-1, [0, 2]] - piece.root[-1, [0, 2]]
        self._frames += piece.num_frames
        return moved

    def report(self) -> dict:
        """:func:`path_report` of the pieces followed so far."""
        return path_report(self.path, strides=self.strides, distance_m=self.distance_m)


def estimated_path(rec: Recording, placement: str, height_m: float | None = None
                   ) -> BodyPath | None:
    """The path ``placement``'s estimator reads from ``rec``; None for a placement without
    one (:data:`imuloco.paths.registry.ESTIMATORS`)."""
    return estimate_path(rec, placement, height_m) if placement in ESTIMATORS else None


def follow_recording(motion: Motion, rec: Recording, placement: str,
                     height_m: float | None = None) -> tuple[Motion, dict | None]:
    """``motion`` (reconstructed from ``rec``, frame 0 at its first sample) following the path
    that ``placement``'s estimator (:mod:`imuloco.paths.registry`) reads from ``rec``, and its
    :func:`path_report`; unchanged and None for a placement without an estimator."""
    path = estimated_path(rec, placement, height_m)
    if path is None:
        return motion, None
    followed = follow(motion, path)
    return followed, path_report(path, followed)
