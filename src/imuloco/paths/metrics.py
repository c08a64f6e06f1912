"""How far a path (:class:`imuloco.paths.base.BodyPath`) is from the truth's: the figures of
issue 40, pure functions of two paths (or two motions, through
:func:`imuloco.paths.truth.path_of_motion`).

- distance walked: the length of the pelvis's path once the sway within a step is averaged out
  (a centred average over SWAY_S, :func:`walked_distance`), so that a path estimated at the
  pelvis's mean and a motion capture's swaying pelvis are measured alike; the ratio to the
  truth's and its error in per cent;
- stride length: the mean over the path's strides against the truth's mean (metres and per
  cent);
- end-point error: the distance between the two paths' last points once the estimate is turned
  to set off in the truth's direction (both start at the origin), in per cent of the distance
  the truth walked.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np

from imuloco.core.motion import Motion
from imuloco.paths.base import BodyPath
from imuloco.paths.geometry import initial_yaw, rotate, smooth_over
from imuloco.paths.truth import path_of_motion

SWAY_S = 0.5  # a step: the pelvis sways left and right once per step
PATH_KEYS = ("distance_m", "truth_distance_m", "distance_ratio", "distance_error_pct",
             "stride_length_m", "truth_stride_length_m", "stride_error_m", "stride_error_pct",
             "end_point_error_pct")


def walked_distance(path: BodyPath, sway_s: float = SWAY_S) -> float:
    """The length (metres) of ``path``'s pelvis path averaged over ``sway_s`` seconds."""
    t, xy = np.asarray(path.times_s, float), np.asarray(path.root_xy, float)
    if len(t) < 2 or t[-1] <= t[0]:
        return 0.0
    rate = (len(t) - 1) / (t[-1] - t[0])
    smooth = smooth_over(xy, rate, sway_s)
    return float(np.linalg.norm(np.diff(smooth, axis=0), axis=1).sum())


def mean_stride(path: BodyPath) -> float:
    """The mean length of ``path``'s strides, metres (NaN when it has none)."""
    lengths = [s.length_m for s in path.strides if math.isfinite(s.length_m)]
    return float(np.mean(lengths)) if lengths else math.nan


def end_point_error(path: BodyPath, truth: BodyPath) -> float:
    """Metres between the last points of ``path`` and ``truth`` once ``path`` is turned about
    the origin to set off in ``truth``'s direction (the direction to the first point a
    quarter of the distance, at most 1 m, away)."""
    reach = min(1.0, 0.25 * max(walked_distance(truth), 1e-9))
    turn = initial_yaw(truth.root_xy, reach) - initial_yaw(path.root_xy, reach)
    est = rotate(np.asarray(path.root_xy[-1], float), turn)
    return float(np.linalg.norm(est - truth.root_xy[-1]))


def path_errors(path: BodyPath, truth: BodyPath) -> dict[str, float]:
    """The figures of the module docstring (keys :data:`PATH_KEYS`; NaN where undefined)."""
    d, d0 = walked_distance(path), walked_distance(truth)
    s, s0 = mean_stride(path), mean_stride(truth)
    ratio = d / d0 if d0 > 0 else math.nan
    stride_err = s - s0
    return {"distance_m": d, "truth_distance_m": d0, "distance_ratio": ratio,
            "distance_error_pct": 100 * (ratio - 1),
            "stride_length_m": s, "truth_stride_length_m": s0, "stride_error_m": stride_err,
            "stride_error_pct": 100 * stride_err / s0 if s0 > 0 else math.nan,
            "end_point_error_pct": 100 * end_point_error(path, truth) / d0 if d0 > 0
            else math.nan}


def motion_path_errors(motion: Motion, truth: Motion) -> dict[str, float]:
    """:func:`path_errors` of a reconstructed motion's own path against the truth's."""
    return path_errors(path_of_motion(motion), path_of_motion(truth))


def summarize(rows: Iterable[dict[str, float]]) -> dict[str, float]:
    """Mean absolute errors over clips: ``distance_mae_pct``, ``stride_mae_pct``,
    ``stride_mae_m``, ``end_point_error_pct`` (mean) and ``clips`` (NaNs left out)."""
    rows = list(rows)

    def mae(key: str) -> float:
        v = np.array([r[key] for r in rows], float)
        v = v[np.isfinite(v)]
        return float(np.mean(np.abs(v))) if len(v) else math.nan

    return {"distance_mae_pct": mae("distance_error_pct"), "stride_mae_pct":
            mae("stride_error_pct"), "stride_mae_m": mae("stride_error_m"),
            "end_point_error_pct": mae("end_point_error_pct"), "clips": float(len(rows))}
