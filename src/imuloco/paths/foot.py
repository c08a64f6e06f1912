"""The path of a walker from a foot (shoe) sensor: the foot's zero-velocity trajectory.

The foot's swings, rests and level frame are :func:`imuloco.sensors.foottrack.foot_track`'s
(gaitmap); its path is a strapdown integration between its rests with zero-velocity updates
(:func:`imuloco.sensors.foottrack.anchored_track`, lever arm 0), or foot_track's own path
(gaitmap's ``RtsKalman``, ``trajectory="rts"``); a footfall is each stance's stillest moment
(``FootTrack.rest``), where the foot rests on the floor, and a stride the foot's move from one
to the next (the lengths :func:`imuloco.measures.sensorgait.foot_gait` reports). The pelvis
moves with the mean of the two feet when the recording has both; with one foot it is that
foot's path averaged over one stride period (a centred moving average: the foot alternates
ahead of and behind the pelvis), moved half a step width to the body's centre.
"""

from __future__ import annotations

import numpy as np

from imuloco.core.recording import Recording
from imuloco.errors import UnknownNameError
from imuloco.paths.base import BodyPath, Footfall, strides_from_footfalls
from imuloco.paths.geometry import (
    HALF_STEP_WIDTH_M,
    footfalls_at,
    initial_yaw,
    pelvis_of_limb,
    rotate,
    smooth_over,
    still_path,
    stride_period,
    walking_heading,
)
from imuloco.sensors.foottrack import NoWalking, anchored_track, foot_track

FEET = ("right_foot", "left_foot")
NOTE = ("foot-zupt: distance, stride lengths and footfalls from the foot's zero-velocity "
        "trajectory, trusted to a few per cent; the heading drifts slowly "
        "with the gyroscope's bias (yaw is not observable). {pelvis}")


def _foot_xy(rec: Recording, placement: str, trajectory: str
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """The foot's floor path (T, 2) in its own floor frame (origin at its first rest, x along
    its first move), its times (T,), its rests (K,) and the grid's rate; a still path and no
    rests when the foot never walks."""
    k = rec.placements.index(placement)
    try:
        track = foot_track(rec.times, rec.acc[:, k], rec.gyro[:, k])
    except NoWalking:
        return np.zeros((len(rec.times), 2)), rec.times, np.zeros(0, int), rec.rate
    path, rest = anchored_track(track)
    if len(rest) < 2:
        return np.zeros((len(track.times), 2)), track.times, np.zeros(0, int), track.rate
    if trajectory == "rts":
        path = track.path
    xy = path[:, :2] - path[rest[0], :2]
    xy = rotate(xy, -initial_yaw(xy[rest]))
    return xy, track.times, np.asarray(rest, int), track.rate


class FootZupt:
    """:class:`imuloco.paths.base.PathEstimator` of a foot sensor (module docstring)."""

    name = "foot-zupt"
    reads_all_sensors = True  # both feet's tracks, when the recording has both (docstring)
    TRAJECTORIES = ("rts", "anchored")

    def __init__(self, trajectory: str = "anchored") -> None:
        # "anchored": the strapdown of :func:`imuloco.sensors.foottrack.anchored_track` between foot_track's
        # rests, in its level frame; "rts": foot_track's own path (gaitmap's RtsKalman). On
        # virtual feet (the sample's walks, phone noise) anchored's distance is off by 1.7-2.8 %
        # where rts's is off by 9-18 % (its orientation goes astray on some simulated feet:
        # half the stride on a left foot of bandai-namco-1); on the real checks both pass
        # (docs/results/path/README.md)
        self.trajectory = trajectory

    def estimate(self, rec: Recording, placement: str, height_m: float | None = None
                 ) -> BodyPath:
        if placement not in FEET:
            raise UnknownNameError(f"foot-zupt estimates a path from {FEET}, got {placement!r}")
        if placement not in rec.placements:
            raise UnknownNameError(f"recording has no sensor at {placement!r}; it has "
                                   f"{rec.placements}")
        feet = [placement] + [f for f in FEET if f != placement and f in rec.placements]
        if self.trajectory not in self.TRAJECTORIES:
            raise UnknownNameError(f"foot-zupt trajectory must be one of {self.TRAJECTORIES}, "
                                   f"got {self.trajectory!r}")
        tracks = [_foot_xy(rec, f, self.trajectory) for f in feet]
        walking = [tr for tr in tracks if len(tr[2])]
        if not walking:
            return still_path(tracks[0][1], self.name, "the foot never walks: no stride")
        if len(walking) == 2 and len(walking[0][0]) == len(walking[1][0]):
            # both feet, each started half a step width beside the pelvis (floor y is left)
            paths = [xy + np.array([0.0, (-1 if f == "right_foot" else 1) * HALF_STEP_WIDTH_M])
                     for f, (xy, *_) in zip(feet, tracks)]
            times, rate = tracks[0][1], tracks[0][3]
            root = (paths[0] + paths[1]) / 2
            root_walk = smooth_over(root, rate, 0.2)  # the ZUPT paths' jitter, not the sway
            heading = walking_heading(smooth_over(root, rate, stride_period(
                times[tracks[0][2]])), rate)
            pelvis = "The pelvis is the mean of the two feet's paths."
            ff_paths = paths
        else:
            xy, times, rest, rate = tracks[0]
            foot = placement.split("_")[0]
            if len(rest):
                root_walk, heading = pelvis_of_limb(xy, times, rest, rate, foot)
            else:  # this foot stands while the other walks: its path, a second's average
                root_walk = smooth_over(xy, rate, 1.0)
                heading = walking_heading(root_walk, rate)
            pelvis = ("The pelvis is the foot's path averaged over one stride, half a step "
                      "width to the body's centre: its turns are smoothed over a stride.")
            ff_paths = [xy]
            feet = feet[:1]
        origin = root_walk[0].copy()
        root_xy = root_walk - origin
        footfalls: list[Footfall] = []
        for f, xy, tr in zip(feet, ff_paths, tracks):
            footfalls += footfalls_at(f.split("_")[0], tr[1], xy - origin, tr[2], 1.0)
        footfalls.sort(key=lambda f: f.time_s)
        return BodyPath(times, root_xy, heading, footfalls,
                        strides_from_footfalls(footfalls), self.name, NOTE.format(pelvis=pelvis),
                        "travel")
