"""Foot contacts from joint heights and speeds, with thresholds that adapt to body size.

A foot part (heel = ankle joint, toe = toe joint) is in contact when it is near the clip's own
floor and nearly still, the rule of Eom et al. 2014 sec. 6.2 ("sufficiently close to the ground
and its velocity is below a threshold", after Kim et al. 2009). Neither paper gives numbers, so
the tolerances here are fractions of the leg length: a skeleton scaled by ``s`` (root included)
gets the same contacts. The floor is the clip's own: a low percentile of each part's heights
over the clip, so the height of the ankle joint above the sole and the floor's own level need
no calibration, measured from a plane that may slope where the clip covers enough ground
(:func:`floor_under`).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
from scipy.optimize import least_squares

from imuloco.core.motion import Motion

FEET = ("left", "right")
SPEED_TOL = 0.8  # leg lengths per second (~0.65 m/s for a 0.8 m leg)
MIN_FLOOR_SPAN = 2.0  # leg lengths of ground covered along a direction to fit a slope along it
MIN_FLOOR_STEPS = 4  # lowest points of still spells needed to fit a slope at all
FLOOR_ROUGHNESS = 0.01  # leg lengths (~8 mm): a step's lowest point farther off the plane than
# this weighs in linearly, not squared (Huber loss), so a step onto something barely tilts it


def floor_height(heights: np.ndarray, percentile: float = 5.0) -> float:
    """The clip's floor level for one body part: a low percentile of its heights.

    heights : ndarray, shape (T, ...), metres; all feet pooled, so a short running clip whose
        feet are each down a third of the time still has floor samples below the percentile.
    """
    heights = np.asarray(heights, dtype=np.float64)
    if heights.size == 0:
        raise ValueError("floor_height: no frames")
    return float(np.percentile(heights, percentile))


def floor_under(
    positions: np.ndarray, still: np.ndarray, leg_length: float, percentile: float = 5.0,
) -> np.ndarray:
    """The floor's height under each foot part at each frame: a plane that may slope.

    Some recorded floors slope: in 13 of the 16 ``cmu-iclone`` walks the ankle's lowest point
    per step rises 5-11 cm over the 4-5 m walked, so with one floor height per clip the later
    steps sat above the heel tolerance (~1.7 cm) and the walks were labelled 44 / 40 % stance
    per foot, 58 / 58 % with this floor (``docs/results/learned/experiments.md``, "A second,
    smaller defect: cmu-iclone's floor slopes"; ``benchmarks/floor_slope.py``: Bandai-Namco's
    flat floors move under 1 point). So the floor's slope is fitted to the lowest point of
    each still spell of each part (one per step), by least squares with a Huber loss (robust to
    a step onto something or a foot paused in the air), as a linear function of the horizontal
    position along each principal direction of those points that spans at least
    ``MIN_FLOOR_SPAN`` leg lengths: none for standing or stepping in place (the floor is then
    level, as before), the walking direction for a straight walk, both for a path that turns.
    The floor's level is then :func:`floor_height` of the heights with the slope taken out.

    Parameters
    ----------
    positions : ndarray, shape (T, F, 3), world positions of a part on F feet, metres, Y up.
    still : ndarray, shape (T, F), bool: the part is slow enough to stand.
    leg_length : metres; the span needed to fit a slope scales with it.
    percentile : see :func:`floor_height`.

    Returns
    -------
    ndarray, shape (T, F), metres.
    """
    heights = positions[..., 1]
    lows = []  # the lowest frame of each still spell, per foot
    for k in range(still.shape[1]):  # a few feet, a few dozen spells: no per-frame loop
        starts, stops, vals = runs(still[:, k])
        lows += [positions[a + np.argmin(heights[a:b, k]), k]
                 for a, b in zip(starts[vals], stops[vals], strict=True)]
    slope = np.zeros_like(heights)
    if len(lows) >= MIN_FLOOR_STEPS:
        lows = np.array(lows)
        centre = lows[:, [0, 2]].mean(axis=0)
        axes = np.linalg.svd(lows[:, [0, 2]] - centre, full_matrices=False)[2].T  # (2, 2)
        along = (lows[:, [0, 2]] - centre) @ axes
        wide = np.ptp(along, axis=0) >= MIN_FLOOR_SPAN * leg_length
        if wide.any():
            # scipy's robust least squares, not sklearn's HuberRegressor: its L-BFGS takes
            # 9-120 ms a fit here (OpenBLAS threads on tiny arrays), this 1.5 ms
            design = np.c_[np.ones(len(lows)), along[:, wide]]
            fit = least_squares(lambda w: design @ w - lows[:, 1],
                                np.r_[np.median(lows[:, 1]), np.zeros(wide.sum())],
                                jac=lambda w: design, loss="huber",
                                f_scale=FLOOR_ROUGHNESS * leg_length)
            slope = ((positions[..., [0, 2]] - centre) @ axes)[..., wide] @ fit.x[1:]
    return slope + floor_height(heights - slope, percentile)


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
    sloped_floor: bool = True,
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
    sloped_floor : heights from a floor that may slope (:func:`floor_under`); False: from one
        level over the clip (:func:`floor_height`).

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
    step = np.linalg.norm(np.diff(positions, axis=0), axis=-1) * fps  # (T-1, F)
    # still on at least one side: a strike frame is still afterwards, a lift-off frame before
    speed = np.minimum(np.concatenate([step[:1], step]), np.concatenate([step, step[-1:]]))
    still = speed < speed_tol * leg_length
    floor = (floor_under(positions, still, leg_length, floor_percentile) if sloped_floor
             else floor_height(positions[..., 1], floor_percentile))
    raw = (positions[..., 1] - floor < height_tol * leg_length) & still
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
    **tolerances : passed to :func:`part_contacts` (``speed_tol``, ``sloped_floor``, ...).

    Returns
    -------
    dict with keys ``left_heel``, ``left_toe``, ``left_foot``, ``right_heel``, ``right_toe``,
    ``right_foot``, each an ndarray of shape (T,), bool.
    """
    def compute() -> dict[str, np.ndarray]:
        pos = motion.part_positions([f"{s}_{p}" for p in ("ankle", "toe") for s in FEET])
        leg = motion.skeleton.leg_length()
        heel = part_contacts(pos[:, :2], motion.fps, leg, heel_height_tol, **tolerances)
        toe = part_contacts(pos[:, 2:], motion.fps, leg, toe_height_tol, **tolerances)
        out: dict[str, np.ndarray] = {}
        for k, side in enumerate(FEET):
            out[f"{side}_heel"] = heel[:, k]
            out[f"{side}_toe"] = toe[:, k]
            out[f"{side}_foot"] = heel[:, k] | toe[:, k]
        for v in out.values():
            v.flags.writeable = False  # kept: shared by every caller
        return out

    # found once per motion and tolerances: the pinning, gait, checks and path all ask
    key = ("foot_contacts", heel_height_tol, toe_height_tol, *sorted(tolerances.items()))
    return dict(motion.kept(key, compute))


def flat_foot_pitch(motions: Iterable[Motion]) -> float | None:
    """The pitch of a foot flat on the floor in ``motions``, radians: the median over both feet
    and every frame whose heel and toe are both in contact
    (:func:`foot_contacts`) of the ankle-to-toe direction's angle against the
    horizontal (negative: the toe joint below the ankle joint). A property of the rig and its
    capture (-39.6 degrees on Bandai-Namco's), where a landing foot still rolls onto the
    floor. None when no frame has a flat foot (a training set of sprints, say: a model then
    holds a flat foot at the pitch it lands with)."""
    pitches = []
    for m in motions:
        if m.num_frames < 2:
            continue
        c = foot_contacts(m)
        both = foot_pitches(m.skeleton, m.positions())
        for k, side in enumerate(FEET):
            pitches.append(both[c[f"{side}_heel"] & c[f"{side}_toe"], k])
    pitches = np.concatenate(pitches) if pitches else np.zeros(0)
    return float(np.median(pitches)) if pitches.size else None


def foot_pitches(skeleton, positions: np.ndarray) -> np.ndarray:
    """The ankle-to-toe direction's angle against the horizontal (Y up), radians, of the
    :data:`FEET` in every pose: joint positions (T, J, 3) of ``skeleton`` -> (T, 2), negative
    where the toe joint is lower."""
    d = np.stack([positions[:, skeleton.part(f"{s}_toe")]
                  - positions[:, skeleton.part(f"{s}_ankle")] for s in FEET], axis=1)
    return np.arctan2(d[..., 1], np.linalg.norm(d[..., [0, 2]], axis=-1))
