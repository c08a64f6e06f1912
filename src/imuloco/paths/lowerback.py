"""The path of a walker from a lower-back (L5) sensor: bout-wise steps and the trunk's yaw.

Distance comes from the steps Mobilise-D's pipeline finds and measures
(:func:`imuloco.measures.sensorgait.lower_back_gait`: mobgap's gait sequences, initial
contacts, Zijlstra's inverted-pendulum step length, its stride selection and walking bouts).
The pelvis advances one step from each initial contact to the next, of either foot
(:func:`walking_steps`: half the length of the kept strides that cover the step, along the
arc the trunk turned on, :func:`along_path`), at the rhythm of the steps around it, and half
a step beyond the first and last contacts of each run of steps (:func:`step_speed`); outside
the steps it stands. Steps, not strides: a stride whose contacts' sides mobgap's left/right
classifier swapped lasts one step or three, and moving the pelvis by a stride's length over
that time made it race or crawl (ipol-gait bouts up to +86 %, docs/results/path/lower-back.md).
The heading is the gyroscope's rate about the vertical (the mean specific force's direction,
:func:`imuloco.sensors.calibration.body_axes`) integrated, so the path turns where the trunk
turned. Footfalls are the strides' contacts, half a step width beside the pelvis on the
stride's foot's side: where the feet land is not measured, only when (their confidence
FOOTFALL_CONFIDENCE).
"""

from __future__ import annotations

from dataclasses import replace
from itertools import pairwise

import numpy as np
from scipy.integrate import cumulative_trapezoid
from scipy.ndimage import median_filter

from imuloco.core.recording import Recording
from imuloco.errors import UnknownNameError
from imuloco.measures.sensorgait import (
    L5_HEIGHT_RATIO,
    LOWER_BACK,
    MAX_STRIDE_S,
    chord_factor,
    lower_back_gait,
)
from imuloco.ops.filters import resample_uniform
from imuloco.paths.base import BodyPath, Footfall, Stride
from imuloco.paths.geometry import HALF_STEP_WIDTH_M
from imuloco.paths.shank import DEFAULT_HEIGHT_M
from imuloco.sensors.calibration import body_axes

RATE = 100.0
FOOTFALL_CONFIDENCE = 0.3  # positions inferred from the pelvis's, not measured
MAX_STEP_S = MAX_STRIDE_S / 2  # a longer interval between two contacts is a pause
# Where the pelvis is at a contact: half way between the feet, a step length apart (the
# double support that ends one inverted-pendulum vault and starts the next, Zijlstra & Hof
# 2003). From standing, feet side by side, to the first contact it travels half a step, and
# from the last contact of a walk to standing again half a step: EDGE_STEPS of a step.
EDGE_STEPS = 0.5
# A step's rhythm: the median duration of this many steps around it (mobgap's CadFromIc
# smooths its step times with HampelFilter(2, 3.0), two steps each side: five).
STEP_TIME_WINDOW = 5
STRIDE_CONFIDENCE = 0.7  # Zijlstra's pendulum: ~10 % on straight walks (ipol-gait, real)
NOTE = ("lower-back-steps: distance from Mobilise-D's steps (mobgap, Zijlstra's inverted "
        "pendulum step length scaled to the sensor's height), trusted to about 10 %; heading "
        "from the trunk's yaw rate, which drifts slowly with the gyroscope's bias; footfall "
        "positions are inferred beside the pelvis, not measured.")


class LowerBackSteps:
    """:class:`imuloco.paths.base.PathEstimator` of a lower-back sensor (module docstring)."""

    name = "lower-back-steps"

    def __init__(self, edge_steps: float = EDGE_STEPS) -> None:
        self.edge_steps = edge_steps  # steps walked beyond a run's first and last contacts

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
        strides = [Stride(s["foot"], s["start_s"], s["end_s"], s["length_m"], s["speed_mps"],
                          STRIDE_CONFIDENCE) for s in gait.strides if np.isfinite(s["length_m"])]
        speed = step_speed(times, gait.initial_contacts, along_path(strides, times, heading),
                           self.edge_steps)
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


def along_path(strides: list[Stride], times: np.ndarray, heading: np.ndarray) -> list[Stride]:
    """The strides with their lengths along the path they turned on: a stride's reported
    length is the chord between its contacts (:func:`imuloco.measures.sensorgait.
    chord_factor` of the angle turned), the pendulum's the arc the pelvis vaulted along,
    which the path walks while its heading turns (the chord there would shorten a turn
    twice). times, heading : (T,) the path's grid and yaw (radians)."""
    turn = np.abs(np.interp([s.end_s for s in strides], times, heading)
                  - np.interp([s.start_s for s in strides], times, heading))
    return [replace(s, length_m=s.length_m / float(c))
            for s, c in zip(strides, chord_factor(turn))]


def walking_steps(contacts: np.ndarray, strides: list[Stride]) -> np.ndarray:
    """The steps walked: (K, 3) rows of start and end (s) and length (m).

    A step runs from one initial contact to the next (either foot's), at most MAX_STEP_S
    apart, and counts where a kept stride covers its middle; its length is half the mean
    length of the strides covering it (Zijlstra's step lengths, which Mobilise-D averages
    per second and doubles into strides)."""
    ic = np.unique(np.asarray(contacts, float))
    rows = []
    for a, b in pairwise(ic):
        mid = 0.5 * (a + b)
        cover = [s.length_m for s in strides if s.start_s <= mid < s.end_s]
        if b - a <= MAX_STEP_S and cover:
            rows.append((a, b, 0.5 * float(np.mean(cover))))
    return np.array(rows, float).reshape(-1, 3)


def step_speed(times: np.ndarray, contacts: np.ndarray, strides: list[Stride],
               edge_steps: float = EDGE_STEPS) -> np.ndarray:
    """The pelvis's speed (T,) m/s at ``times`` (T,): inside each run of successive steps
    (:func:`walking_steps`) each step's length over the run's step time around it (the median
    of STEP_TIME_WINDOW steps' durations, so that a contact missed or found twice changes
    the rhythm of no step, as Mobilise-D's cadence is robust to them), and ``edge_steps`` of
    a step beyond the run's first and last contacts at their steps' speeds; 0 elsewhere."""
    speed = np.zeros(len(times))
    steps = walking_steps(contacts, strides)
    if len(steps) == 0:
        return speed
    breaks = np.flatnonzero(steps[1:, 0] > steps[:-1, 1]) + 1
    for run in np.split(steps, breaks):
        step_s = median_filter(run[:, 1] - run[:, 0], STEP_TIME_WINDOW, mode="nearest")
        v = run[:, 2] / step_s
        for (a, b, _), vk in zip(run, v):
            speed[(times >= a) & (times < b)] = vk
        if edge_steps > 0:
            # only where no step walks: runs are apart, their edges may meet in a gap
            speed[(times >= run[0, 0] - edge_steps * step_s[0]) & (times < run[0, 0])
                  & (speed == 0)] = v[0]
            speed[(times >= run[-1, 1]) & (times < run[-1, 1] + edge_steps * step_s[-1])
                  & (speed == 0)] = v[-1]
    return speed
