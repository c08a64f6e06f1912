"""Shared geometry of the path estimators: the floor frame, the pelvis from one limb's path,
the walking direction, and a limb's footfalls."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.ndimage import uniform_filter1d

from imuloco.paths.base import BodyPath, Footfall

# Half the step width: walkers' feet land about 0.1 m apart (heel centre to heel centre; Perry
# & Burnfield 2010, Gait Analysis, ch. 1), so each ankle passes ~0.05 m beside the pelvis.
HALF_STEP_WIDTH_M = 0.05
MIN_WALK_SPEED = 0.1  # m/s: slower, the direction of travel is noise and the heading is held
HEADING_REACH_M = 0.5  # the initial heading: direction to the first point this far away


def initial_yaw(xy: np.ndarray, reach_m: float = HEADING_REACH_M) -> float:
    """The direction (radians) from ``xy[0]`` to the first point at least ``reach_m`` away
    (to the farthest when none is), 0 when the points never move. xy : (N, 2)."""
    d = np.linalg.norm(xy - xy[0], axis=1)
    if len(d) == 0 or d.max() < 1e-6:
        return 0.0
    far = np.flatnonzero(d >= reach_m)
    k = int(far[0]) if len(far) else int(np.argmax(d))
    v = xy[k] - xy[0]
    return float(np.arctan2(v[1], v[0]))


def rotate(xy: np.ndarray, angle: float) -> np.ndarray:
    """Points (..., 2) turned by ``angle`` radians (counter-clockwise)."""
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([c * xy[..., 0] - s * xy[..., 1], s * xy[..., 0] + c * xy[..., 1]], -1)


def stride_period(footfall_times: np.ndarray, max_stride_s: float = 3.0) -> float:
    """The median interval between successive footfalls of one foot shorter than
    ``max_stride_s`` (pauses left out); 1.1 s, a typical walking stride, when there is none."""
    d = np.diff(np.sort(footfall_times))
    d = d[(d > 0) & (d <= max_stride_s)]
    return float(np.median(d)) if len(d) else 1.1


def smooth_over(xy: np.ndarray, rate: float, period_s: float) -> np.ndarray:
    """A centred moving average of ``xy`` (T, 2) on a uniform grid at ``rate`` Hz over
    ``period_s`` seconds: over one stride, where one limb's path puts the pelvis on average
    (the limb alternates ahead of and behind it).

    Within half a period of either end the window is not full: there the average is carried
    on at the pace of the half period next to it (linear extrapolation), not averaged over
    fewer samples, which would put the pelvis where the limb happened to be when the
    recording started or stopped (up to half a stride off). A path shorter than two periods
    is padded by point reflection instead."""
    xy = np.asarray(xy, float)
    n = min(max(1, round(period_s * rate)), len(xy))
    if len(xy) < 2 or n < 2:
        return xy.copy()
    h = n // 2
    if len(xy) >= 2 * n + 2:
        avg = uniform_filter1d(xy, n, axis=0, mode="nearest")
        a, b = h, len(xy) - 1 - h  # the first and last samples with a full window
        k = max(1, h)
        head = (avg[a + k] - avg[a]) / k
        tail = (avg[b] - avg[b - k]) / k
        avg[:a] = avg[a] - np.outer(np.arange(a, 0, -1), head)
        avg[b + 1:] = avg[b] + np.outer(np.arange(1, len(xy) - b), tail)
        return avg
    head = 2 * xy[0] - xy[h + 1:0:-1] if h + 1 < len(xy) else 2 * xy[0] - xy[:0:-1]
    tail = 2 * xy[-1] - xy[-2:-h - 3:-1] if h + 1 < len(xy) else 2 * xy[-1] - xy[-2::-1]
    padded = np.concatenate([head, xy, tail])
    return uniform_filter1d(padded, n, axis=0, mode="nearest")[len(head):len(head) + len(xy)]


def walking_heading(xy: np.ndarray, rate: float) -> np.ndarray:
    """The direction of travel (radians, unwrapped) of a smooth path (T, 2) at ``rate`` Hz,
    held where it moves slower than MIN_WALK_SPEED (the first moving value before)."""
    v = np.gradient(xy, axis=0) * rate if len(xy) > 1 else np.zeros_like(xy)
    moving = np.linalg.norm(v, axis=1) >= MIN_WALK_SPEED
    if not moving.any():
        return np.zeros(len(xy))
    yaw = np.arctan2(v[:, 1], v[:, 0])
    idx = np.where(moving, np.arange(len(xy)), 0)
    np.maximum.accumulate(idx, out=idx)
    idx[: int(np.argmax(moving))] = int(np.argmax(moving))
    return np.unwrap(yaw[idx])


def beside(xy: np.ndarray, heading: np.ndarray, foot: str) -> np.ndarray:
    """Points (T, 2) moved HALF_STEP_WIDTH_M towards the body's centre from a ``foot``'s
    path: to the left of the heading for the right foot, to the right for the left."""
    side = 1.0 if foot == "right" else -1.0
    left = np.stack([-np.sin(heading), np.cos(heading)], -1)
    return xy + side * HALF_STEP_WIDTH_M * left


def pelvis_of_limb(xy: np.ndarray, times: np.ndarray, steps: np.ndarray, rate: float,
                   foot: str) -> tuple[np.ndarray, np.ndarray]:
    """The pelvis's floor path (T, 2) and heading (T,) rad from one limb's path ``xy``
    (T, 2) at ``times`` (T,) s, ``rate`` Hz: the path averaged over one stride period (of its
    ``steps``, the samples of its footfalls or mid-stances: the limb alternates ahead of and
    behind the pelvis), moved half a step width towards the body's centre (:func:`beside`)."""
    mean = smooth_over(xy, rate, stride_period(times[steps]))
    heading = walking_heading(mean, rate)
    return beside(mean, heading, foot), heading


def footfalls_at(foot: str, times: np.ndarray, xy: np.ndarray, index: np.ndarray,
                 confidence: np.ndarray | float = 1.0) -> list[Footfall]:
    """One footfall of ``foot`` at each sample of ``index``, at ``xy`` (T, 2) there."""
    conf = np.broadcast_to(np.asarray(confidence, float), (len(index),))
    return [Footfall(foot, float(times[i]), np.asarray(xy[i], float).copy(),
                     float(np.clip(c, 0.0, 1.0))) for i, c in zip(index, conf)]


def still_path(times: np.ndarray, source: str, why: str) -> BodyPath:
    """A path that stays where it started (no walking), saying why in its note."""
    return BodyPath(np.asarray(times, float), np.zeros((len(times), 2)), None, [], [], source,
                    f"{source}: no path ({why})")


def from_start(path: BodyPath, t0: float) -> BodyPath:
    """``path`` with its times counted from ``t0`` (the recording's first sample), as
    :class:`~imuloco.paths.base.BodyPath` states them."""
    if t0 == 0:
        return path
    return replace(path, times_s=path.times_s - t0,
                   footfalls=[replace(f, time_s=f.time_s - t0) for f in path.footfalls],
                   strides=[replace(s, start_s=s.start_s - t0, end_s=s.end_s - t0)
                            for s in path.strides])
