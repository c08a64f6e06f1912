"""Gait measured from one sensor's raw signal, by the method that suits where it is worn.

- Foot (``right_foot``, ``left_foot``; on the shoe over the instep): the swings and the
  stances' rest moments of :func:`imuloco.sensors.foottrack.foot_track`, and the foot's
  zero-velocity-update path of :func:`imuloco.sensors.foottrack.anchored_track`, the one the
  ``foot-zupt`` path estimator gives the animation (so the report's strides are the
  animation's). A stride's length is the horizontal distance between the foot's rest
  positions (Rampp et al. 2015). Initial and terminal contacts come from
  gaitmap's ``HerzerEventDetection`` (Rampp's gyroscope events refined with the forward
  acceleration; its IC search on the gyroscope low-passed at 6 Hz, and reaching the stance
  after the contact, where a running foot lands) on strides segmented at the swings' starts.
  gaitmap's Barth DTW segmentation and Rampp event detection live in ``gaitmap_mad``
  (AGPL-3.0), which this MIT package does not depend on; the swings need no template.
- Lower back (``lower_back``, L5): Mobilise-D's published pipeline from ``mobgap`` (Iluz gait
  sequence detection, Ionescu initial contacts, Ullrich left/right, Zijlstra's inverted-pendulum
  step length with Mobilise-D's published scaling factor, stride selection and walking-bout
  assembly), on body axes found from gravity and the fore-aft sway
  (:func:`imuloco.sensors.calibration.body_axes`). A stride's length is the chord of the
  pelvis's path over it (:func:`chord_factor`): the pendulum measures the travel along the
  path, a reference the displacement between two contacts of one foot.

A placement's ``gait`` (:data:`imuloco.sensors.placement.PRESETS`) names its estimator in
:data:`ESTIMATORS`; placements without one are measured on the reconstructed motion.

Every figure is derived from the same strides, so they agree by construction:
``speed = stride length x cadence / 120`` and ``steps = 2 x strides`` for a foot sensor.
A recording too short or without walking is :class:`SensorGait` with ``measured False`` and a
``reason``, never zeros.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from imuloco.core.motion import Motion
from imuloco.errors import MissingExtraError, UnknownNameError
from imuloco.measures.gait import Gait, gait_parameters, stature, to_json
from imuloco.measures.strides import stride_rows
from imuloco.ops.filters import resample_uniform
from imuloco.phases import gait_phases
from imuloco.phases.gait import GaitPhases
from imuloco.sensors.calibration import body_axes
from imuloco.sensors.foottrack import NoWalking, anchored_track, foot_track
from imuloco.sensors.placement import PRESETS

LOWER_BACK = "lower_back"
# L5 sits at about the greater trochanter's height, 0.530 x body height (Winter 2009,
# Biomechanics and Motor Control of Human Movement, Fig. 4.1), when the sensor's height is
# not measured.
L5_HEIGHT_RATIO = 0.530
MIN_STRIDES = 2
MAX_STRIDE_S = 3.0  # the longest stride (Kluge et al. 2021, Mobilise-D's stride definition)
GYRO_CUTOFF_HZ = 6.0  # walking kinematics' low-pass cutoff (Winter 2009), see foot_gait
HERZER_IC_SHARE = 0.7  # gaitmap's HerzerEventDetection searches the IC in a stride's first 70 %


@dataclass
class SensorGait:
    """Gait of one recording from one sensor.

    Attributes
    ----------
    placement, method : where the sensor was and what measured the gait.
    measured : False when no gait could be measured; ``reason`` says why.
    strides : one dict per stride (:func:`stride_row`): ``foot``, ``start_s``, ``end_s`` (its
        initial contacts), ``duration_s``, ``length_m``, ``speed_mps``, ``stance_s``,
        ``swing_s`` (NaN when unknown), ``confidence`` (None).
    initial_contacts : ndarray (K,), seconds, every initial contact found (of the worn foot
        for a foot sensor, of both feet for the lower back).
    steps_per_contact : steps the walker takes per initial contact found (2 for one foot).
    times, path : ndarray (T,) and (T, 3), the sensor's path in metres, x and y on the floor,
        z up (foot sensors), or None.
    swings_m : ndarray (K,), a foot sensor's horizontal distance (m) moved in the swing that
        ends at each initial contact, from the rest before it to the rest after (the first
        swing from standing included, which no stride's length covers); with both feet's
        contacts (a reconstruction's strikes), each its own foot's swing; None otherwise.
    """

    placement: str
    method: str
    measured: bool = True
    reason: str = ""
    strides: list[dict] = field(default_factory=list)
    initial_contacts: np.ndarray = field(default_factory=lambda: np.zeros(0))
    steps_per_contact: int = 1
    times: np.ndarray | None = None
    path: np.ndarray | None = None
    swings_m: np.ndarray | None = None

    def window(self, start: float, end: float) -> SensorGait:
        """The same gait restricted to strides and contacts within ``[start, end]`` s."""
        ic = self.initial_contacts
        keep = (ic >= start) & (ic <= end)
        return SensorGait(self.placement, self.method, self.measured, self.reason,
                          [s for s in self.strides if s["start_s"] >= start and
                           s["end_s"] <= end],
                          ic[keep], self.steps_per_contact, self.times, self.path,
                          None if self.swings_m is None else self.swings_m[keep])

    def summary(self) -> dict[str, float]:
        """``steps``, ``strides``, ``cadence_spm``, ``stride_length_m``, ``step_length_m``,
        ``speed_mps``, ``stance_pct``, ``swing_pct`` (NaN where undefined). Cadence counts the
        contacts over the time they span, pauses left out: an interval between two contacts
        longer than a stride lasts (MAX_STRIDE_S; half of it between both feet's contacts) is
        no step. Speed is stride length x cadence / 120, so ``speed = step_length x cadence /
        60`` holds exactly."""
        ic = np.sort(self.initial_contacts)
        nan = math.nan
        steps = float(len(ic) * self.steps_per_contact) if self.measured else nan
        gaps = np.diff(ic)
        gaps = gaps[gaps <= MAX_STRIDE_S * self.steps_per_contact / 2]
        span = float(gaps.sum())
        cadence = 60.0 * self.steps_per_contact * len(gaps) / span if span > 0 else nan
        lengths = np.array([s["length_m"] for s in self.strides], dtype=float)
        lengths = lengths[np.isfinite(lengths)]
        stride = float(np.mean(lengths)) if len(lengths) else nan
        stance = np.array([s["stance_s"] / s["duration_s"] for s in self.strides], float)
        stance = float(100 * np.nanmean(stance)) if np.isfinite(stance).any() else nan
        return {"steps": steps, "strides": float(len(self.strides)),
                "cadence_spm": cadence if self.measured else nan,
                "stride_length_m": stride, "step_length_m": stride / 2.0,
                "speed_mps": stride * cadence / 120.0,
                "stance_pct": stance, "swing_pct": 100 - stance}

    def to_json(self) -> dict:
        """JSON-ready: placement, method, measured, reason, summary and per-stride rows."""
        return {"placement": self.placement, "method": self.method,
                "measured": self.measured, "reason": self.reason or None,
                "summary": to_json(self.summary()),
                "strides": [{k: (v if isinstance(v, str) or v is None else
                                 to_json({"v": v})["v"]) for k, v in s.items()}
                            for s in self.strides]}


def stride_row(foot: str, start: float, end: float, length: float, stance: float) -> dict:
    """A stride in the fields of :data:`imuloco.measures.strides.STRIDE_FIELDS` (times in
    seconds, ``stance`` the share of the stride in contact, NaN when unknown)."""
    dur = end - start
    return {"foot": foot, "start_s": start, "end_s": end, "duration_s": dur,
            "length_m": length, "speed_mps": length / dur, "stance_s": stance * dur,
            "swing_s": (1 - stance) * dur, "confidence": None}


def not_measured(placement: str, method: str, reason: str) -> SensorGait:
    """A :class:`SensorGait` saying that no gait could be measured and why."""
    return SensorGait(placement, method, measured=False, reason=reason)


FOOT_METHOD = ("zero-velocity strapdown trajectory between the stances' rests (the foot-zupt "
               "path the animation follows), strides from swing to swing, "
               "HerzerEventDetection contacts")


def foot_gait(times: np.ndarray, acc: np.ndarray, gyro: np.ndarray, foot: str = "right",
              placement: str | None = None) -> SensorGait:
    """Gait from a foot-worn IMU (see the module docstring).

    Parameters
    ----------
    times : ndarray, shape (T,), seconds.
    acc, gyro : ndarray, shape (T, 3), m/s² (+9.81 up at rest) and rad/s, in any sensor axes.
    foot : ``"right"`` or ``"left"``.
    """
    placement = placement or f"{foot}_foot"
    try:
        track = foot_track(times, acc, gyro)  # checks that gaitmap is installed
    except NoWalking as e:
        return not_measured(placement, FOOT_METHOD, str(e))
    import pandas as pd
    from gaitmap.data_transform import ButterworthFilter
    from gaitmap.event_detection import HerzerEventDetection
    from gaitmap.utils.coordinate_conversion import (
        convert_left_foot_to_fbf,
        convert_right_foot_to_fbf,
    )

    starts, rest, t, fsf = track.starts, track.rest, track.times, track.level
    pos = anchored_track(track)[0]  # the path the animation follows (foot-zupt's)
    fbf = (convert_right_foot_to_fbf if foot == "right" else convert_left_foot_to_fbf)(fsf)
    # segmented strides from the start of one swing (heel off, just before toe off) to the
    # next; the last swing's is one typical stride long (its contact counts too)
    ends = np.append(starts[1:], min(len(fsf) - 1, starts[-1] + int(np.median(np.diff(starts)))))
    seg = pd.DataFrame({"s_id": np.arange(len(starts)), "start": starts,
                        "end": ends}).set_index("s_id")
    # Herzer bounds its IC search by the first of the gyroscope's most prominent swing peaks,
    # which an impact spike at toe off can be on some shoes (IC then 0.3-0.5 s early, in 7 % of
    # ipol-gait's strides): the IC is searched on the gyroscope low-passed at 6 Hz, the cutoff
    # Winter found for walking's kinematics (Biomechanics and Motor Control of Human Movement,
    # 2009), and on the unfiltered one where that finds none (a jogging stride's swing peak can
    # blur into its toe off); the contact itself is found on the acceleration, and the toe off
    # on the unfiltered gyroscope. Every stride keeps its row (NaN where nothing was found).
    smooth = fbf.copy()
    gyr = ["gyr_pa", "gyr_ml", "gyr_si"]
    smooth[gyr] = ButterworthFilter(order=2, cutoff_freq_hz=GYRO_CUTOFF_HZ).filter(
        fbf[gyr], sampling_rate_hz=track.rate).filtered_data_
    # Herzer also ends its IC search at 70 % of the stride, where a walking foot has landed;
    # a running one lands later (its swing from heel off is 60-70 % of the stride). The IC
    # searches get each stride at least long enough for 70 % of it to reach the stillest
    # moment of the stance after the contact, which the contact precedes; a walking stride
    # is mostly long enough already.
    reach = starts + np.ceil((rest[1:] - starts) / HERZER_IC_SHARE).astype(int)
    seg_ic = seg.assign(end=np.minimum(np.maximum(ends, reach), len(fsf) - 1))
    found = []
    for data, events, strides in ((smooth, ("ic",), seg_ic), (fbf, ("ic",), seg_ic),
                                  (fbf, ("tc",), seg)):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            found.append(HerzerEventDetection(enforce_consistency=False, detect_only=events
                                              ).detect(data, stride_list=strides,
                                                       sampling_rate_hz=track.rate
                                                       ).annotated_original_event_list_
                         .reindex(seg.index))
    ic = found[0]["ic"].fillna(found[1]["ic"]).to_numpy(float)
    tc = found[2]["tc"].to_numpy(float)
    rows = []
    # stride k: from its initial contact to the next one; its length is the distance between
    # the foot's rest positions of the stances that follow those contacts
    for k in range(len(ic) - 1):
        if not (np.isfinite(ic[k]) and np.isfinite(ic[k + 1])):
            continue
        a, b = int(ic[k]), int(ic[k + 1])
        length = float(np.linalg.norm(pos[rest[k + 2], :2] - pos[rest[k + 1], :2])) if (
            k + 2 < len(rest)) else math.nan
        stance = (tc[k + 1] - a) / (b - a) if np.isfinite(tc[k + 1]) else math.nan
        if not (0 < stance < 1):
            stance = math.nan
        rows.append(stride_row(foot, float(t[a]), float(t[b]), length, stance))
    ics = t[ic[np.isfinite(ic)].astype(int)]
    if len(rows) < MIN_STRIDES:
        return not_measured(placement, FOOT_METHOD, f"{len(rows)} stride(s) with both "
                            "contacts found: no walking")
    # swing k (its contact ic[k]) moves the foot from rest k to rest k + 1
    swing_m = np.linalg.norm(np.diff(pos[rest, :2], axis=0), axis=1)[np.isfinite(ic)]
    return SensorGait(placement, FOOT_METHOD, strides=rows, initial_contacts=ics,
                      steps_per_contact=2, times=t, path=pos, swings_m=swing_m)


BACK_METHOD = ("mobgap MobilisedPipelineHealthy (Mobilise-D P1: GsdIluz, IcdIonescu, LrcUllrich, "
               "CadFromIc, SlZijlstra with the all-participants factor, stride selection, "
               "walking-bout assembly); each stride's length the chord of the path the pelvis "
               "turned along in it")


def chord_factor(turn_rad: np.ndarray | float) -> np.ndarray:
    """Chord over arc length of a circular path turning ``turn_rad`` (radians):
    ``sin(θ/2) / (θ/2)``, 1 when straight, 2√2/π for a quarter turn.

    The inverted pendulum (Zijlstra & Hof 2003) measures how far the body vaults along its
    path; a stride's length is the straight distance between two contacts of one foot. On a
    path of radius R the two feet land at R ± half the step width, and their chords average
    to the pelvis's chord, 2R sin(θ/2), whatever the width."""
    return np.sinc(np.asarray(turn_rad, float) / (2 * np.pi))  # numpy's sinc is sin(πx)/(πx)


def turned(yaw_rate: np.ndarray, rate: float, starts: np.ndarray, ends: np.ndarray
           ) -> np.ndarray:
    """Absolute angle (the rate's unit x s) turned from sample ``starts`` to ``ends``, the
    rate about the vertical integrated."""
    angle = np.concatenate([[0.0], np.cumsum(yaw_rate) / rate])
    return np.abs(angle[np.asarray(ends, int)] - angle[np.asarray(starts, int)])


def even_rate(times: np.ndarray) -> float:
    """The even whole rate (Hz) nearest the mean rate of ``times``, that of the lower back's
    uniform grid.

    mobgap spreads its per-second values over the strides from second centres of
    ``round(rate / 2)`` samples and a padding ``rate`` samples before the first: where the
    rounding goes up (99.3 Hz, or 100 Hz with float noise) a stride starting with its gait
    sequence falls before the interpolation's range and mobgap raises ValueError."""
    mean = (len(times) - 1) / (times[-1] - times[0])
    return 2.0 * max(1, round(mean / 2))


def lower_back_gait(times: np.ndarray, acc: np.ndarray, gyro: np.ndarray,
                    sensor_height_m: float, chord: bool = True) -> SensorGait:
    """Gait from a lower-back (L5) IMU by Mobilise-D's published pipeline (mobgap's
    ``MobilisedPipelineHealthy``, its published defaults), on the body axes of
    :func:`imuloco.sensors.calibration.body_axes`.

    Two choices are ours: Zijlstra's step length takes Mobilise-D's scaling factor fitted on
    all participants (``step_length_scaling_factor_ms_all``), not the pipeline's default one
    fitted on people with multiple sclerosis only, as imuloco's users are anyone; and the
    steps are every initial contact found in the gait sequences, while the strides (their
    lengths) are those the stride selection and walking-bout assembly keep.

    Against the hand-assembled chain it replaces (Iluz, Ionescu, Zijlstra's raw step lengths
    summed two by two), each walking bout's stride error is the same within 0.2 points
    (ipol-gait's 200 bouts, mobilise-d-lab's 17): the library takes over the stride assembly
    and names each stride's foot (Ullrich), at 2.5 times the CPU time.

    Parameters
    ----------
    times : ndarray, shape (T,), seconds.
    acc, gyro : ndarray, shape (T, 3), m/s² and rad/s, in any sensor axes.
    sensor_height_m : the sensor's height above the floor (the pendulum's length), metres;
        :data:`L5_HEIGHT_RATIO` x body height when not measured.
    chord : each stride's length is the pendulum's times :func:`chord_factor` of the angle
        the sensor turned about the vertical between its contacts; False: the pendulum's, as
        Mobilise-D publishes it. On mobilise-d-lab the chord alone takes the stride error
        from 17.9 to 15.3 % (daily living 36.2 to 30.2 %, straight walks unchanged); on
        ipol-gait's straight bouts it stays 8.6 % (``docs/results/real/experiments.md``).
    """
    try:
        from sklearn.exceptions import InconsistentVersionWarning

        with warnings.catch_warnings():
            # mobgap ships Ullrich's left/right classifier as a scikit-learn 1.6 pickle (of
            # the package, not the user's), which a newer scikit-learn loads with a warning;
            # its feet agree with ipol-gait's hand-checked ones (test_lower_back.py)
            warnings.simplefilter("ignore", InconsistentVersionWarning)
            from mobgap.data import GaitDatasetFromData
            from mobgap.pipeline import MobilisedPipelineHealthy
            from mobgap.stride_length import SlZijlstra
    except ImportError as e:
        raise MissingExtraError("lower-back gait", f"mobgap ({e})", "gait") from None
    import pandas as pd  # after the check: the [gait] extra brings it

    times = np.asarray(times, float)
    if len(times) < 2 or times[-1] - times[0] < 3.0:
        return not_measured(LOWER_BACK, BACK_METHOD, "the recording is shorter than 3 s, "
                            "too short for a walking bout")
    rate = even_rate(times)
    x = resample_uniform(times, np.concatenate([acc, np.degrees(gyro)], axis=1), rate)
    axes = body_axes(x[:, :3], rate)
    # mobgap's sensor frame of a Mobilise-D lower-back sensor: x up, y medio-lateral,
    # z forward; acceleration in m/s² with gravity, rotation in deg/s
    frame = pd.DataFrame(np.concatenate([x[:, :3] @ axes.T, x[:, 3:] @ axes.T], axis=1),
                         columns=["acc_x", "acc_y", "acc_z", "gyr_x", "gyr_y", "gyr_z"])
    data = GaitDatasetFromData({"r": {"LowerBack": frame}}, rate,
                               {"r": {"sensor_height_m": float(sensor_height_m)}}, {"r": {}})
    pipe = MobilisedPipelineHealthy(
        stride_length_calculation=SlZijlstra(
            **SlZijlstra.PredefinedParameters.step_length_scaling_factor_ms_all),
        # turns, the per-bout plausibility thresholds (which need a cohort) and the week's
        # aggregates are read by none of the steps whose strides are reported
        turn_detection=None, dmo_thresholds=None, dmo_aggregation=None,
        recommended_cohorts=None)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        pipe.run(data[0])
    if pipe.gs_list_.empty:
        return not_measured(LOWER_BACK, BACK_METHOD, "no walking bout found (Iluz gait "
                            "sequence detection)")
    t = times[0] + np.arange(len(frame)) / rate
    strides = pipe.per_stride_parameters_
    if len(strides) < MIN_STRIDES:
        return not_measured(LOWER_BACK, BACK_METHOD, f"{len(strides)} stride(s) in "
                            "Mobilise-D's walking bouts: no walking")
    # the frame's x is up: its rotation rate is the turning about the vertical, deg/s
    turn = turned(frame["gyr_x"].to_numpy(), rate, strides["start"], strides["end"])
    lengths = strides["stride_length_m"].to_numpy(float) * (
        chord_factor(np.radians(turn)) if chord else 1.0)
    rows = [stride_row(str(s.lr_label), float(t[int(s.start)]), float(t[int(s.end)]),
                       float(length), math.nan)
            for s, length in zip(strides.itertuples(), lengths)]
    return SensorGait(LOWER_BACK, BACK_METHOD, strides=rows,
                      initial_contacts=t[np.sort(pipe.raw_ic_list_["ic"].to_numpy(int))],
                      steps_per_contact=1)


def _foot_sensor_gait(rec, k: int, height_m: float | None,
                     sensor_height_m: float | None) -> SensorGait:
    """:func:`foot_gait` of sensor ``k`` of a Recording (no height needed)."""
    placement = rec.placements[k]
    return foot_gait(rec.times, rec.acc[:, k], rec.gyro[:, k], PRESETS[placement].side,
                     placement)


def _back_sensor_gait(rec, k: int, height_m: float | None,
                      sensor_height_m: float | None) -> SensorGait:
    """:func:`lower_back_gait` of sensor ``k`` of a Recording, its height from the body's
    (:data:`L5_HEIGHT_RATIO`) when not given."""
    if sensor_height_m is None or not np.isfinite(sensor_height_m):
        if height_m is None or not np.isfinite(height_m):
            raise ValueError("lower-back gait needs the walker's height (--height) or the "
                             "sensor's height above the floor")
        sensor_height_m = L5_HEIGHT_RATIO * height_m
    return lower_back_gait(rec.times, rec.acc[:, k], rec.gyro[:, k], sensor_height_m)


# the estimators a placement's ``gait`` names (imuloco.sensors.placement.PRESETS)
ESTIMATORS = {"foot": _foot_sensor_gait, "lower_back": _back_sensor_gait}


def estimator_of(placement: str) -> str | None:
    """The name of ``placement``'s sensor-level gait estimator (:data:`ESTIMATORS`), None for
    a placement whose gait is the reconstructed motion's."""
    p = PRESETS.get(placement)
    return None if p is None else p.gait


def sensor_gait(rec, placement: str, height_m: float | None = None,
                sensor_height_m: float | None = None) -> SensorGait:
    """Gait of the sensor at ``placement`` of a Recording, by the method for that placement.

    ``height_m`` (body height) gives the lower-back sensor's height when ``sensor_height_m``
    is not given; a foot sensor needs neither. Raises KeyError for placements with no
    sensor-level method (the reconstruction's gait serves them).
    """
    k = rec.placements.index(placement)
    estimator = estimator_of(placement)
    if estimator is None:
        raise UnknownNameError(f"no sensor-level gait method for placement {placement!r}; have "
                               f"{[n for n in PRESETS if estimator_of(n)]}")
    return ESTIMATORS[estimator](rec, k, height_m, sensor_height_m)


GAIT_KEYS = ("steps", "cadence_spm", "step_length_m", "stride_length_m", "speed_mps",
             "stance_pct", "swing_pct")


@dataclass
class GaitReport:
    """The gait a study reads for a recording (:func:`gait_report`).

    gait : the parameters (NaN where nothing could be measured: for a sensor, also what it
        does not measure, such as the other foot's stance or the legs' rhythm, so that no
        value mixes two sources).
    source : what measured them; note : why nothing was measured, or None.
    strides : one JSON-ready row per stride (:data:`imuloco.measures.strides.STRIDE_FIELDS`;
        None: not listed).
    motion_gait : for a sensor, the reconstructed motion's own parameters beside it (None
        otherwise, where ``gait`` is that).
    """

    gait: Gait
    source: str
    note: str | None
    strides: list[dict[str, Any]] | None
    motion_gait: Gait | None = None

    def to_json(self) -> dict[str, Any]:
        """``gait``, ``gait_source``, ``gait_note``, ``strides`` and ``motion_gait``."""
        return {"gait": self.gait.to_json(), "gait_source": self.source,
                "gait_note": self.note, "strides": self.strides,
                "motion_gait": None if self.motion_gait is None else self.motion_gait.to_json()}


def gait_report(motion: Motion, rec, placement: str, height_m: float | None = None,
                phases: GaitPhases | None = None) -> GaitReport:
    """The gait a study reads for a recording, from the best estimator for its placement:
    the sensor's own signal for a foot or the lower back (:func:`sensor_gait`), the
    reconstructed motion otherwise (:func:`imuloco.measures.gait.gait_parameters`).
    ``phases``: the motion's :func:`imuloco.phases.gait_phases` when already found.
    """
    phases = gait_phases(motion) if phases is None else phases
    gait = gait_parameters(motion, phases)
    strides = stride_rows(motion, phases)
    source, note, motion_gait = "the reconstructed motion", None, None
    estimator = estimator_of(placement)
    if estimator is not None:
        if height_m is None:
            height_m = stature(motion.skeleton)
            if estimator == "lower_back":
                note = (f"no --height given: the skeleton's stature {height_m:.2f} m sets "
                        "the pendulum length")
        sg = sensor_gait(rec, placement, height_m=height_m)
        summary = sg.summary()
        motion_gait = Gait(**gait)
        gait = {k: (v if k == "duration_s" else math.nan) for k, v in gait.items()}
        gait.update({k: summary[k] for k in GAIT_KEYS})
        if estimator == "foot":  # the worn foot's stance is the sensor's
            gait[f"{PRESETS[placement].side}_stance_pct"] = summary["stance_pct"]
        if summary["swing_pct"] > 0:
            gait["stance_swing_ratio"] = summary["stance_pct"] / summary["swing_pct"]
        strides, source = sg.strides, f"the {placement} sensor's signal: {sg.method}"
        if not sg.measured:
            note = f"no gait could be measured: {sg.reason}"
    elif len(strides) < MIN_STRIDES:
        note = ("no gait could be measured: fewer than 2 strides (strike to strike of one "
                "foot) in the reconstruction")
    if note and note.startswith("no gait"):
        gait = {k: (v if k == "duration_s" else math.nan) for k, v in gait.items()}
    return GaitReport(Gait(**gait), source, note,
                      [{k: (v if isinstance(v, str) or v is None else to_json({"v": v})["v"])
                        for k, v in r.items()} for r in strides], motion_gait)


# A reconstruction's legs against its shank sensor's own swing (docs/results/real/shin-stride):
# on virtual walks the signal's swing is 1.00-1.09 of the truth's shank swing and the two legs
# are within 15 % of each other (10th percentile of left/right 0.85), so a reconstructed leg
# under 0.85 of the signal's swing, or of the other leg's, swings less than the sensor says.
SWING_AGREEMENT = 0.85
CADENCE_AGREEMENT = 0.05  # the legs' rhythm against the signal's (Welch): within 5 %


def model_gait_note(placement: str, gait: dict, signal_cadence_spm: float | None = None,
                    signal_swing_deg: float | None = None,
                    shank_swing_deg: dict[str, float] | None = None) -> str:
    """The ``gait_note`` of a gait read from the reconstructed motion (a shin, thigh or any
    sensor without a gait estimator of its own): that it is model-derived and what the
    sensor's own signal says of it.

    gait : :func:`gait_report`'s ``gait`` (``cadence_rhythm_spm`` is the legs' rhythm).
    signal_cadence_spm, signal_swing_deg : :func:`imuloco.measures.gait.signal_rhythm` of
        the raw sensor (None or NaN: not checked).
    shank_swing_deg : the reconstruction's shank swings, ``{"left": deg, "right": deg}``.
    """
    parts = [("model-derived: cadence, stride, speed and stance come from the reconstructed "
             f"legs, not measured by the {placement} sensor")]
    rhythm = gait.get("cadence_rhythm_spm")
    if _finite(signal_cadence_spm) and _finite(rhythm):
        off = abs(rhythm - signal_cadence_spm) / signal_cadence_spm
        parts.append(f"its cadence {'agrees with' if off <= CADENCE_AGREEMENT else 'differs from'}"
                     f" the sensor's own rhythm ({rhythm:.1f} against {signal_cadence_spm:.1f} "
                     f"steps/min, {100 * off:.1f} % apart)")
    else:
        parts.append("its cadence was not checked against the sensor's own rhythm")
    counted = gait.get("cadence_spm")
    if _finite(counted) and _finite(rhythm) and rhythm > 0 \
            and abs(counted - rhythm) / rhythm > CADENCE_AGREEMENT:
        parts.append(f"the steps counted give {counted:.1f} steps/min, "
                     f"{100 * abs(counted - rhythm) / rhythm:.0f} % off the legs' rhythm: the "
                     "reconstructed feet's contacts, hence steps, stride and stance, are "
                     "unreliable")
    legs = {k: v for k, v in (shank_swing_deg or {}).items() if _finite(v)}
    if _finite(signal_swing_deg) and len(legs) == 2:
        low, high = min(legs.values()), max(legs.values())
        short = high < SWING_AGREEMENT * signal_swing_deg or low < SWING_AGREEMENT * high
        parts.append(
            f"the shank turns {signal_swing_deg:.0f} deg a stride by its own gyroscope, the "
            f"reconstructed shanks {legs.get('right', math.nan):.0f} (right) and "
            f"{legs.get('left', math.nan):.0f} (left) deg: " +
            ("the legs swing less than the sensor says, so stride and speed likely read short "
             "(on a real shin walk 0.80 m was read where at least 1.15 m is likely: "
             "docs/results/real/shin-stride); compare walks of one person, do not quote "
             "them as metres" if short else
             "the legs swing as the sensor says; stride and speed are still the model's "
             "(0.83-0.93 of the truth's on virtual walks)"))
    else:
        parts.append("stride and speed are the model's; nothing model-free checks them for "
                     "this placement")
    return "; ".join(parts) + "."


def _finite(v) -> bool:
    return v is not None and math.isfinite(v)
