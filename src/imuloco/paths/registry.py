"""One table: which path estimator serves which placement (:func:`estimator_for`)."""

from __future__ import annotations

from imuloco.core.recording import Recording
from imuloco.errors import UnknownNameError
from imuloco.paths.base import BodyPath, PathEstimator
from imuloco.paths.foot import FEET, FootZupt
from imuloco.paths.geometry import from_start
from imuloco.paths.lowerback import LowerBackSteps
from imuloco.paths.shank import SHANKS, ShankPivot

ESTIMATORS: dict[str, type] = {
    **{p: ShankPivot for p in SHANKS},
    **{p: FootZupt for p in FEET},
    "lower_back": LowerBackSteps,
}


def estimator_for(placement: str) -> PathEstimator:
    """The path estimator of ``placement``; UnknownNameError for a placement without one."""
    if placement not in ESTIMATORS:
        raise UnknownNameError(f"no path estimator for placement {placement!r}; have "
                               f"{sorted(ESTIMATORS)}")
    return ESTIMATORS[placement]()


def estimate_path(rec: Recording, placement: str, height_m: float | None = None) -> BodyPath:
    """The path of the body from the sensor at ``placement`` of ``rec``, its times counted
    from the recording's first sample."""
    estimator = estimator_for(placement)
    if placement not in rec.placements:
        raise UnknownNameError(f"recording has no sensor at {placement!r}; it has "
                               f"{rec.placements}")
    return from_start(estimator.estimate(rec, placement, height_m), float(rec.times[0]))
