"""Which path estimator serves which placement (:func:`estimator_for`): each placement names its
estimator in its declaration (:attr:`imuloco.sensors.placement.Placement.path_estimator`)."""

from __future__ import annotations

from imuloco.core.recording import Recording
from imuloco.errors import UnknownNameError
from imuloco.paths.base import BodyPath, PathEstimator
from imuloco.paths.foot import FootZupt
from imuloco.paths.geometry import from_start
from imuloco.paths.lowerback import LowerBackSteps
from imuloco.paths.shank import ShankPivot
from imuloco.sensors.placement import PRESETS

BY_NAME: dict[str, type] = {c.name: c for c in (ShankPivot, FootZupt, LowerBackSteps)}
ESTIMATORS: dict[str, type] = {name: BY_NAME[p.path_estimator] for name, p in PRESETS.items()
                               if p.path_estimator is not None}


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
