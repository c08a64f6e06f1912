"""Gait events: contact onsets and offsets, ankle crossing events, cadence.

The crossing event (CE) of Mousas 2017 sec. 4.2 says whether one ankle is in front of or behind
the other. It is measured along the body's heading (the hip line crossed with the vertical, see
:mod:`imuloco.ops.heading`), so it does not depend on where the clip walks in the world.
"""

from __future__ import annotations

import numpy as np

from imuloco.ops.filters import gaussian_smooth
from imuloco.ops.heading import heading_from_hips, to_heading_frame


def onsets(mask: np.ndarray) -> np.ndarray:
    """Frames where a 1-D boolean array turns True (a True first frame is not an onset)."""
    mask = np.asarray(mask, dtype=bool)
    return np.flatnonzero(mask[1:] & ~mask[:-1]) + 1


def offsets(mask: np.ndarray) -> np.ndarray:
    """First False frames after True runs (a False first frame is not an offset)."""
    mask = np.asarray(mask, dtype=bool)
    return np.flatnonzero(~mask[1:] & mask[:-1]) + 1


def heading_angle(left_hip: np.ndarray, right_hip: np.ndarray, sigma: float = 0.0) -> np.ndarray:
    """Heading (radians, about +Y) from the hip line, unwrapped and optionally smoothed.

    left_hip, right_hip : ndarray, shape (T, 3), metres.
    sigma : Gaussian smoothing in frames; it damps the pelvis's yaw swing within a stride.
    """
    theta = np.unwrap(heading_from_hips(left_hip, right_hip))
    return gaussian_smooth(theta, sigma) if sigma > 0 else theta


def forward_difference(
    right_ankle: np.ndarray, left_ankle: np.ndarray, origin: np.ndarray, theta: np.ndarray
) -> np.ndarray:
    """How far the right ankle is ahead of the left along the heading, metres.

    right_ankle, left_ankle, origin : ndarray, shape (..., 3), world positions (origin: pelvis).
    theta : ndarray, shape (...), heading angle.

    Returns
    -------
    ndarray, shape (...): positive when the right ankle leads.
    """
    pts = to_heading_frame(np.stack([right_ankle, left_ankle], axis=-2), origin, theta)
    return pts[..., 0, 2] - pts[..., 1, 2]  # heading frame: +Z is forward


def right_ahead(diff: np.ndarray, tol: float) -> np.ndarray:
    """Which ankle leads, with hysteresis: the state flips only when ``diff`` passes ``±tol``.

    diff : ndarray, shape (T,), :func:`forward_difference`.
    tol : metres; feet side by side (standing) then do not chatter.

    Returns
    -------
    ndarray, shape (T,), bool: True while the right ankle leads.
    """
    diff = np.asarray(diff, dtype=np.float64)
    decided = np.abs(diff) > tol
    if not decided.any():
        return diff > 0
    # forward-fill the last decided sign; frames before the first decision take its sign
    idx = np.where(decided, np.arange(diff.size), -1)
    idx = np.maximum.accumulate(idx)
    idx[idx < 0] = np.flatnonzero(decided)[0]
    return diff[idx] > 0


def crossing_events(ahead: np.ndarray) -> dict[str, np.ndarray]:
    """Crossing events from the leading-ankle state.

    ahead : ndarray, shape (T,), bool, :func:`right_ahead`.

    Returns
    -------
    dict: ``right`` (RCE, the right ankle passes the left going forward) and ``left`` (LCE),
    frame indices where the sign of the forward difference changes.
    """
    return {"right": onsets(ahead), "left": offsets(ahead)}


def cadence(strikes: list[np.ndarray] | tuple[np.ndarray, ...], fps: float) -> float:
    """Steps per minute from foot-strike frames of all feet: the number of intervals between
    consecutive strikes over the time they span. NaN with fewer than two strikes.

    strikes : sequence of int arrays, frame indices of each foot's strikes.
    """
    all_strikes = np.sort(np.concatenate([np.asarray(s, dtype=np.int64) for s in strikes]))
    if all_strikes.size < 2 or all_strikes[-1] == all_strikes[0]:
        return float("nan")
    return float(60.0 * fps * (all_strikes.size - 1) / (all_strikes[-1] - all_strikes[0]))
