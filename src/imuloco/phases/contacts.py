"""Foot contacts from joint heights and speeds, with thresholds that adapt to body size.

A foot part (heel = ankle joint, toe = toe joint) is in contact when it is near the clip's own
floor and nearly still, the rule of Eom et al. 2014 sec. 6.2 ("sufficiently close to the ground
and its velocity is below a threshold", after Kim et al. 2009). Neither paper gives numbers, so
the tolerances here are fractions of the leg length: a skeleton scaled by ``s`` (root included)
gets the same contacts. The floor is a low percentile of each part's heights over the clip, so
the height of the ankle joint above the sole and the floor's own level need no calibration.
"""

from __future__ import annotations

import numpy as np

from imuloco.core.motion import Motion

FEET = ("left", "right")
SPEED_TOL = 0.8  # leg lengths per second (~0.65 m/s for a 0.8 m leg)


def floor_height(heights: np.ndarray, percentile: float = 5.0) -> float:
    """The clip's floor level for one body part: a low percentile of its heights.

    heights : ndarray, shape (T, ...), metres; all feet pooled, so a short running clip whose
        feet are each down a third of the time still has floor samples below the percentile.
    """
    heights = np.asarray(heights, dtype=np.float64)
    if heights.size == 0:
        raise ValueError("floor_height: no frames")
    return float(np.percentile(heights, percentile))


def runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Run-length encoding of a 1-D boolean array: starts, stops (exclusive), values."""
    mask = np.asarray(mask, dtype=bool)
    if mask.ndim != 1:
        raise ValueError(f"runs: expected a 1-D mask, got shape {mask.shape}")
    if mask.size == 0:
        e = np.zeros(0, dtype=np.int64)
        return e, e, np.zeros(0, dtype=bool)
    edges = np.flatnonzero(mask[1:] != mask[:-1]) + 1
    starts = np.concatenate([[0], edges])
    stops = np.concatenate([edges, [mask.size]])
    return starts, stops, mask[starts]


def clean_mask(mask: np.ndarray, max_gap: int, min_length: int) -> np.ndarray:
    """Fill short gaps, then drop short blips, along axis 0.

    ``scipy.ndimage.binary_closing``/``opening`` would do this but erode runs that touch the
    clip's ends (the border counts as False), so runs are edited directly.

    mask : ndarray, shape (T, ...), bool
    max_gap : False runs of at most this many frames with True on both sides become True.
    min_length : True runs shorter than this many frames become False.
    """
    mask = np.asarray(mask, dtype=bool)
    flat = mask.reshape(mask.shape[0], -1).copy()
    for k in range(flat.shape[1]):  # a few feet: the loop is over columns, not frames
        starts, stops, vals = runs(flat[:, k])
        vals = vals | ((starts > 0) & (stops < len(flat)) & (stops - starts <= max_gap))
        col = np.repeat(vals, stops - starts)
        starts, stops, vals = runs(col)
        flat[:, k] = np.repeat(vals & (stops - starts >= min_length), stops - starts)
    return flat.reshape(mask.shape)


def part_contacts(
    positions: np.ndarray,
    fps: float,
    leg_length: float,
    height_tol: float = 0.03,
    speed_tol: float = SPEED_TOL,
    floor_percentile: float = 5.0,
    max_gap_s: float = 0.07,
    min_length_s: float = 0.05,
) -> np.ndarray:
    """Contact of one kind of foot part (all heels, or all toes) from its positions.

    Parameters
    ----------
    positions : ndarray, shape (T, F, 3), world positions of the part on F feet, metres, Y up.
    fps : frames per second.
    leg_length : metres (hip to ankle); the tolerances scale with it.
    height_tol : contact when less than ``height_tol * leg_length`` above the floor.
    speed_tol : and slower than ``speed_tol * leg_length`` per second (3-D speed, the smaller
        of the backward and forward differences).
    floor_percentile : percentile of the pooled heights taken as the floor.
    max_gap_s, min_length_s : cleanup, see :func:`clean_mask`.

    Returns
    -------
    ndarray, shape (T, F), bool
    """
    positions = np.asarray(positions, dtype=np.float64)
    if positions.ndim != 3 or positions.shape[-1] != 3:
        raise ValueError(f"part_contacts: expected positions (T, F, 3), got {positions.shape}")
    if leg_length <= 0 or fps <= 0:
        raise ValueError(f"part_contacts: leg_length and fps must be positive, got "
                         f"{leg_length} and {fps}")
    if positions.shape[0] < 2:
        raise ValueError("part_contacts: need at least 2 frames")
    height = positions[..., 1] - floor_height(positions[..., 1], floor_percentile)
    step = np.linalg.norm(np.diff(positions, axis=0), axis=-1) * fps  # (T-1, F)
    # still on at least one side: a strike frame is still afterwards, a lift-off frame before
    speed = np.minimum(np.concatenate([step[:1], step]), np.concatenate([step, step[-1:]]))
    raw = (height < height_tol * leg_length) & (speed < speed_tol * leg_length)
    return clean_mask(raw, round(max_gap_s * fps), round(min_length_s * fps))


def foot_contacts(
    motion: Motion, heel_height_tol: float = 0.02, toe_height_tol: float = 0.05,
    **tolerances: float,
) -> dict[str, np.ndarray]:
    """Heel, toe and foot (either) contacts of both feet of a motion.

    Parameters
    ----------
    motion : Motion whose skeleton maps the ``{left,right}_{ankle,toe}`` parts.
    heel_height_tol, toe_height_tol : ``height_tol`` of :func:`part_contacts` for the ankle and
        the toe joint, in leg lengths. The heel's is tight so that heel-off (the start of
        terminal stance) is found when the heel starts to rise, which is slow (the ankle moves
        at under 0.5 m/s then); the toe joint's is loose because it lifts a few cm while the
        foot rolls over the toe tips before toe-off.
    **tolerances : passed to :func:`part_contacts` (``speed_tol``, ...).

    Returns
    -------
    dict with keys ``left_heel``, ``left_toe``, ``left_foot``, ``right_heel``, ``right_toe``,
    ``right_foot``, each an ndarray of shape (T,), bool.
    """
    pos = motion.part_positions([f"{s}_{p}" for p in ("ankle", "toe") for s in FEET])
    leg = motion.skeleton.leg_length()
    heel = part_contacts(pos[:, :2], motion.fps, leg, heel_height_tol, **tolerances)
    toe = part_contacts(pos[:, 2:], motion.fps, leg, toe_height_tol, **tolerances)
    out: dict[str, np.ndarray] = {}
    for k, side in enumerate(FEET):
        out[f"{side}_heel"] = heel[:, k]
        out[f"{side}_toe"] = toe[:, k]
        out[f"{side}_foot"] = heel[:, k] | toe[:, k]
    return out
