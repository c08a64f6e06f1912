"""Which path estimator serves which placement (:func:`estimator_for`): each placement names its
estimator in its declaration (:attr:`imuloco.sensors.placement.Placement.path_estimator`).

A recording with several sensors whose placements declare the same estimator (two shins: two
shank pivots) gives one path from all of them (:func:`fuse_paths`): the root is the mean of
their roots, the heading their circular mean, the footfalls and strides those of every sensor.
An estimator that reads every sensor of its kind itself (``reads_all_sensors``: foot-zupt puts
the pelvis between both feet's zero-velocity tracks) is run once. Sensors with another
estimator, or none (a wrist), leave the path to the primary sensor's.
"""

from __future__ import annotations

import numpy as np

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
    same = [] if getattr(estimator, "reads_all_sensors", False) else [
        p for p in rec.placements if p != placement
        and PRESETS[p].path_estimator == PRESETS[placement].path_estimator]
    paths = [from_start(estimator.estimate(rec, p, height_m), float(rec.times[0]))
             for p in [placement, *same]]
    return fuse_paths(paths, [placement, *same]) if same else paths[0]


def fuse_paths(paths: list[BodyPath], placements: list[str]) -> BodyPath:
    """One path from several sensors' paths of one estimator (the module docstring's rule),
    on the first one's times: each root interpolated there and averaged, headings averaged
    on the circle (None where one is unknown), footfalls and strides of all, in time order.
    Each path's floor frame is its sensor's initial heading: sensors that start walking
    together share it."""
    t = paths[0].times_s
    root = np.mean([np.stack([np.interp(t, p.times_s, p.root_xy[:, k]) for k in range(2)], 1)
                    for p in paths], axis=0)
    heading = None
    if all(p.heading_rad is not None for p in paths):
        c = np.mean([np.interp(t, p.times_s, np.cos(p.heading_rad)) for p in paths], axis=0)
        s = np.mean([np.interp(t, p.times_s, np.sin(p.heading_rad)) for p in paths], axis=0)
        heading = np.arctan2(s, c)
    return BodyPath(t, root, heading,
                    sorted((f for p in paths for f in p.footfalls), key=lambda f: f.time_s),
                    sorted((s for p in paths for s in p.strides), key=lambda s: s.start_s),
                    paths[0].source,
                    f"{paths[0].note} Averaged over the {len(paths)} sensors at "
                    f"{', '.join(placements)}.", paths[0].heading_kind)
