"""The path of a walker from a lower-back (L5) sensor: bout-wise steps and the trunk's yaw.

Distance comes from the strides Mobilise-D's pipeline finds and measures
(:func:`imuloco.measures.sensorgait.lower_back_gait`: mobgap's gait sequences, initial
contacts, Zijlstra's inverted-pendulum step length): inside each stride the pelvis moves at
that stride's length over its duration (the strides of both feet that cover a moment
averaged), outside every stride it stands. The heading is the gyroscope's rate about the
vertical (the mean specific force's direction, :func:`imuloco.sensors.calibration.body_axes`)
integrated, so the path turns where the trunk turned. Footfalls are the strides' contacts,
half a step width beside the pelvis on the stride's foot's side: where the feet land is not
measured, only when (their confidence FOOTFALL_CONFIDENCE).
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import cumulative_trapezoid

from imuloco.core.recording import Recording
from imuloco.errors import UnknownNameError
from imuloco.measures.sensorgait import L5_HEIGHT_RATIO, LOWER_BACK, lower_back_gait
from imuloco.ops.filters import resample_uniform
from imuloco.paths.base import BodyPath, Footfall, Stride
from imuloco.paths.geometry import HALF_STEP_WIDTH_M
from imuloco.paths.shank import DEFAULT_HEIGHT_M
from imuloco.sensors.calibration import body_axes

RATE = 100.0
FOOTFALL_CONFIDENCE = 0.3  # positions inferred from the pelvis's, not measured
STRIDE_CONFIDENCE = 0.7  # Zijlstra's pendulum: ~10 % on straight walks (ipol-gait, real)
NOTE = ("lower-back-steps: distance from Mobilise-D's strides (mobgap, Zijlstra's inverted "
        "pendulum step length scaled to the sensor's height), trusted to about 10 %; heading "
        "from the trunk's yaw rate, which drifts slowly with the gyroscope's bias; footfall "
        "positions are inferred beside the pelvis, not measured.")


class LowerBackSteps:
    """:class:`imuloco.paths.base.PathEstimator` of a lower-back sensor (module docstring)."""

    name = "lower-back-steps"

    def estimate(self, rec: Recording, placement: str = LOWER_BACK,
                 height_m: float | None = None) -> BodyPath:
        if placement != LOWER_BACK:
            raise UnknownNameError(f"lower-back-steps estimates a path from {LOWER_BACK!r}, "
                                   f"got {placement!r}")
        k = rec.placements.index(placement)
        times = rec.times[0] + np.arange(max(2, round((rec.times[-1] - rec.times[0]) * RATE)
                                         + 1)) / RATE
        gait = lower_back_gait(rec.times, rec.acc[:, k], rec.gyro[:, k],
                               L5_HEIGHT_RATIO * (height_m or DEFAULT_HEIGHT_M))
        if not gait.measured:
            return BodyPath(times, np.zeros((len(times), 2)), None, [], [], self.name,
                            f"{self.name}: no path ({gait.reason})")
        x = resample_uniform(rec.times, np.concatenate([rec.acc[:, k], rec.gyro[:, k]], 1),
                             RATE)[:len(times)]
        times = times[:len(x)]
        up = body_axes(x[:, :3], RATE)[0]
        heading = cumulative_trapezoid(x[:, 3:] @ up, dx=1.0 / RATE, initial=0.0)
        speed, cover = np.zeros(len(times)), np.zeros(len(times))
        strides = []
        for s in gait.strides:
            if not np.isfinite(s["length_m"]):
                continue
            inside = (times >= s["start_s"]) & (times < s["end_s"])
            speed[inside] += s["speed_mps"]
            cover[inside] += 1
            strides.append(Stride(s["foot"], s["start_s"], s["end_s"], s["length_m"],
                                  s["speed_mps"], STRIDE_CONFIDENCE))
        speed = np.divide(speed, cover, out=np.zeros_like(speed), where=cover > 0)
        vel = speed[:, None] * np.stack([np.cos(heading), np.sin(heading)], -1)
        root = cumulative_trapezoid(vel, dx=1.0 / RATE, axis=0, initial=0.0)
        footfalls = []
        for s in strides:
            for t in (s.start_s, s.end_s):
                i = min(len(times) - 1, round((t - times[0]) * RATE))
                side = -1.0 if s.foot == "right" else 1.0  # floor y is to the left
                left = np.array([-np.sin(heading[i]), np.cos(heading[i])])
                footfalls.append(Footfall(s.foot, float(t), root[i] + side * HALF_STEP_WIDTH_M
                                          * left, FOOTFALL_CONFIDENCE))
        # a contact ends one stride and starts the next of its foot: keep one footfall each
        seen, unique = set(), []
        for f in sorted(footfalls, key=lambda f: f.time_s):
            if (f.foot, round(f.time_s, 3)) not in seen:
                seen.add((f.foot, round(f.time_s, 3)))
                unique.append(f)
        # the root moves along the trunk's yaw: a direction of travel (forward walking assumed)
        return BodyPath(times, root, heading, unique, strides, self.name, NOTE, "travel")
