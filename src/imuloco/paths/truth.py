"""The ground truth's own path: the path a motion's root and feet took (to check estimators).

The root's horizontal trajectory, the facing heading from the hip line, one footfall per
contact of each foot (:func:`imuloco.phases.contacts.foot_contacts`) at its middle frame
(mid-stance), where the ankle rests, and the strides between successive footfalls of a foot.
"""

from __future__ import annotations

import numpy as np

from imuloco.core.motion import Motion
from imuloco.ops.heading import wrap_angle
from imuloco.paths.base import BodyPath, Footfall, strides_from_footfalls, to_floor
from imuloco.phases.contacts import FEET, foot_contacts, runs
from imuloco.phases.events import heading_angle

HEADING_SIGMA_S = 0.5  # damps the pelvis's yaw swing within a stride (about one stride long)


def facing(motion: Motion) -> np.ndarray:
    """The hips' facing (T,), radians about +Y: the hip line crossed with the vertical,
    unwrapped and smoothed over HEADING_SIGMA_S (about a stride)."""
    pos = motion.part_positions(["left_hip", "right_hip"])
    return heading_angle(pos[:, 0], pos[:, 1], HEADING_SIGMA_S * motion.fps)


def path_of_motion(motion: Motion, heading_from: str = "hips") -> BodyPath:
    """The path of ``motion``'s root (joint 0) and feet, in its floor frame.

    heading_from : ``"hips"``: the floor's x axis is the facing at the first frame (the hip
    line crossed with the vertical, smoothed over HEADING_SIGMA_S).
    """
    if heading_from != "hips":
        raise ValueError(f"heading_from must be 'hips', got {heading_from!r}")
    ankles = motion.part_positions(["left_ankle", "right_ankle"])
    theta = facing(motion)
    theta0 = float(theta[0])
    origin = motion.root[0]
    root_xy = to_floor(motion.root, origin, theta0)
    contacts = foot_contacts(motion)
    footfalls = []
    times = motion.times
    for k, foot in enumerate(FEET):
        starts, stops, vals = runs(contacts[f"{foot}_foot"])
        for a, b in zip(starts[vals], stops[vals]):
            mid = (int(a) + int(b) - 1) // 2
            footfalls.append(Footfall(foot, float(times[mid]),
                                      to_floor(ankles[mid, k], origin, theta0), 1.0))
    footfalls.sort(key=lambda f: f.time_s)
    return BodyPath(times, root_xy, np.unwrap(wrap_angle(theta - theta0)), footfalls,
                    strides_from_footfalls(footfalls), "truth",
                    "the motion's own root trajectory and ankle footfalls (ground truth)")
