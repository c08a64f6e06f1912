"""Spatio-temporal gait parameters of one motion, as a gait laboratory reports them.

From the foot strikes and contacts that :func:`imuloco.phases.gait_phases` detects:

- ``cadence_spm``: steps per minute (both feet).
- ``cadence_rhythm_spm``: cadence from the stride frequency of the ankles' alternation
  (:func:`motion_cadence`), robust to spurious strikes in jittery reconstructions.
- ``steps``: number of foot strikes (left + right).
- ``speed_mps``: walking speed, the horizontal distance the pelvis travelled from the first to
  the last strike divided by that time (so standing at the start or end does not count).
- ``step_length_m``: the distance covered per step, ``60 x speed / cadence``, and
  ``stride_length_m`` twice that: consistent with speed and cadence by construction. (The
  ankles' separation at a strike, ``ankle_step_length_m``, the "heel to heel" step length, is
  shorter than the distance covered per step when running: the flight adds to it.)
- ``ankle_stride_length_m``: the median horizontal distance the striking ankle travelled
  between two strikes of the same foot (:func:`imuloco.measures.strides.stride_rows` has
  each stride).
- ``stance_pct`` / ``swing_pct``: per foot, the share of the frames between that foot's first
  and last strike (whole gait cycles) spent in contact / in the air; ``stance_swing_ratio`` is
  stance over swing (about 60/40 = 1.5 in normal walking, Perry and Burnfield 2010).
- ``double_support_pct``: share of the frames between the first and the last strike with both
  feet down.

Lengths are in metres, so they depend on the skeleton's size (the training skeleton's for a
reconstruction). Values that need more strikes than the motion has are NaN (``None`` in JSON).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from scipy.signal import butter, sosfiltfilt, welch

from imuloco.core.motion import Motion
from imuloco.limits import MAX_HEIGHT_M, MIN_HEIGHT_M
from imuloco.measures.metrics import foot_skate
from imuloco.ops.filters import resample_linear
from imuloco.phases import foot_contacts, gait_phases
from imuloco.phases.events import forward_difference, heading_angle
from imuloco.phases.gait import GaitPhases

FEET = ("left", "right")
SIGNAL_RATE_HZ = 50.0  # a raw signal's grid for its cadence and swing


def _median(values: list[float] | np.ndarray) -> float:
    values = np.asarray(values, dtype=np.float64)
    return float(np.median(values)) if values.size else math.nan


def _cycle_share(mask: np.ndarray, strikes: np.ndarray) -> float:
    """Fraction of True frames of ``mask`` (T,) over whole cycles, first to last strike."""
    if len(strikes) < 2:
        return math.nan
    return float(np.mean(mask[strikes[0]:strikes[-1]]))


def gait_parameters(motion: Motion, phases: GaitPhases | None = None) -> dict[str, float]:
    """Spatio-temporal gait parameters of ``motion`` (see the module docstring).

    Parameters
    ----------
    motion : a walking (or running) Motion whose skeleton maps pelvis, hips and ankles.
    phases : its :func:`imuloco.phases.gait_phases` when already computed.

    Returns
    -------
    dict of floats (NaN where undefined): ``duration_s``, ``steps``, ``cadence_spm``,
    ``cadence_rhythm_spm``, ``step_length_m``, ``stride_length_m``, ``ankle_step_length_m``,
    ``ankle_stride_length_m``, ``speed_mps``, ``{left,right}_stance_pct``,
    ``stance_pct``, ``swing_pct``, ``stance_swing_ratio``, ``double_support_pct``.
    """
    ph = gait_phases(motion) if phases is None else phases
    fps = motion.fps
    pos = motion.part_positions(["pelvis", "left_hip", "right_hip", "left_ankle", "right_ankle"])
    theta = heading_angle(pos[:, 1], pos[:, 2], 0.1 * fps)
    ahead = forward_difference(pos[:, 4], pos[:, 3], pos[:, 0], theta)  # right minus left, m
    ankle = {"left": pos[:, 3], "right": pos[:, 4]}

    step_lengths, stride_lengths = [], []
    for foot in FEET:
        strikes = ph.steps[foot]
        sign = 1.0 if foot == "right" else -1.0
        step_lengths += list(sign * ahead[strikes])
        horiz = ankle[foot][strikes][:, [0, 2]]
        stride_lengths += list(np.linalg.norm(np.diff(horiz, axis=0), axis=-1))

    all_strikes = np.sort(np.concatenate([ph.steps[f] for f in FEET]))
    if len(all_strikes) >= 2 and all_strikes[-1] > all_strikes[0]:
        a, b = all_strikes[0], all_strikes[-1]
        path = np.linalg.norm(np.diff(pos[a:b + 1, 0, :][:, [0, 2]], axis=0), axis=-1).sum()
        speed = float(path / ((b - a) / fps))
        both = ph.contacts["left_foot"] & ph.contacts["right_foot"]
        double = float(np.mean(both[a:b]))
    else:
        speed = double = math.nan

    stance = {f: _cycle_share(ph.contacts[f"{f}_foot"], ph.steps[f]) for f in FEET}
    known = [v for v in stance.values() if not math.isnan(v)]
    mean_stance = float(np.mean(known)) if known else math.nan
    swing = 1.0 - mean_stance
    ratio = mean_stance / swing if swing > 0 else math.nan
    step = 60.0 * speed / ph.cadence_spm if ph.cadence_spm > 0 else math.nan
    return {
        "duration_s": float(motion.duration),
        "steps": float(len(all_strikes)),
        "cadence_spm": float(ph.cadence_spm),
        "cadence_rhythm_spm": motion_cadence(motion),
        "step_length_m": step,
        "stride_length_m": 2.0 * step,
        "ankle_step_length_m": _median(step_lengths),
        "ankle_stride_length_m": _median(stride_lengths),
        "speed_mps": speed,
        "left_stance_pct": 100.0 * stance["left"],
        "right_stance_pct": 100.0 * stance["right"],
        "stance_pct": 100.0 * mean_stance,
        "swing_pct": 100.0 * swing,
        "stance_swing_ratio": ratio,
        "double_support_pct": 100.0 * double,
    }


@dataclass(frozen=True)
class Gait:
    """The gait parameters of one walk (:func:`gait_parameters`' keys, module docstring), as
    a report carries them: floats, NaN where undefined; :meth:`to_json` rounds them (None for
    NaN), in this order."""

    duration_s: float
    steps: float
    cadence_spm: float
    cadence_rhythm_spm: float
    step_length_m: float
    stride_length_m: float
    ankle_step_length_m: float
    ankle_stride_length_m: float
    speed_mps: float
    left_stance_pct: float
    right_stance_pct: float
    stance_pct: float
    swing_pct: float
    stance_swing_ratio: float
    double_support_pct: float

    @classmethod
    def of(cls, motion: Motion, phases: GaitPhases | None = None) -> Gait:
        """:func:`gait_parameters` of ``motion`` (``phases``: its gait phases if known)."""
        return cls(**gait_parameters(motion, phases))

    def to_dict(self) -> dict[str, float]:
        """The parameters by name, as :func:`gait_parameters` returns them."""
        return asdict(self)

    def to_json(self) -> dict[str, float | None]:
        """JSON-ready: rounded to 4 decimals, NaN as None (:func:`to_json`)."""
        return to_json(self.to_dict())


# Stature from the leg: hip joint (greater trochanter) at 0.530 and ankle at 0.039 of body
# height, so hip to ankle is 0.491 of it (Winter 2009, Biomechanics and Motor Control of Human
# Movement, Fig. 4.1, after Drillis and Contini 1966).
LEG_TO_HEIGHT = 0.530 - 0.039
# the body heights taken (height_scale, --height, a walkers file): outside, a number is no
# standing human's height in metres


def stature(skeleton) -> float:
    """Body height (metres) of a skeleton, from its hip-to-ankle length (:data:`LEG_TO_HEIGHT`)."""
    return skeleton.leg_length() / LEG_TO_HEIGHT


def height_scale(skeleton, height_m: float) -> float:
    """The factor that scales ``skeleton`` to a body ``height_m`` metres tall (ValueError
    outside :data:`MIN_HEIGHT_M` to :data:`MAX_HEIGHT_M`)."""
    if not (np.isfinite(height_m) and MIN_HEIGHT_M <= height_m <= MAX_HEIGHT_M):
        raise ValueError(f"height must be a body height in metres ({MIN_HEIGHT_M:g} to "
                         f"{MAX_HEIGHT_M:g}), got {height_m}")
    return height_m / stature(skeleton)


def to_height(motion: Motion, height_m: float) -> Motion:
    """``motion`` on its skeleton scaled to a body of ``height_m`` metres (offsets and root path
    times the ratio of heights; rotations unchanged), so every length and speed measured on it
    is in that body's proportions."""
    k = height_scale(motion.skeleton, height_m)
    return Motion(motion.skeleton.scaled(k), motion.rotations, motion.root * k, motion.fps,
                  motion.name)


def to_json(values: dict[str, float], digits: int = 4) -> dict[str, float | None]:
    """Round floats and turn NaN into ``None`` for JSON."""
    return {k: (None if v is None or (isinstance(v, float) and math.isnan(v))
                else round(float(v), digits)) for k, v in values.items()}


# ---- plausibility of a reconstruction without ground truth --------------------------------
KNEE_LIMITS_DEG = (0.0, 160.0)  # full extension to deep flexion (passive range, adults)
HIP_LIMITS_DEG = (0.0, 130.0)  # thigh against the trunk's downward axis, any direction


def _angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle (...) in degrees between vectors a and b (..., 3)."""
    cos = np.sum(a * b, axis=-1) / np.maximum(
        np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1), 1e-12)
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def knee_flexion(motion: Motion, side: str = "right") -> np.ndarray:
    """Knee flexion (T,) in degrees from joint positions: the angle between the thigh
    (hip to knee) and the shank (knee to ankle) directions, 0 with the leg straight. It does
    not depend on the skeleton's rest-pose conventions."""
    p = motion.part_positions([f"{side}_hip", f"{side}_knee", f"{side}_ankle"])
    return _angle_deg(p[:, 1] - p[:, 0], p[:, 2] - p[:, 1])


def hip_angle(motion: Motion, side: str = "right") -> np.ndarray:
    """Angle (T,) in degrees between the thigh (hip to knee) and the trunk's downward axis
    (neck to pelvis): 0 standing straight, ~90 sitting; flexion, extension and abduction alike."""
    p = motion.part_positions(["neck", "pelvis", f"{side}_hip", f"{side}_knee"])
    return _angle_deg(p[:, 3] - p[:, 2], p[:, 1] - p[:, 0])


def _swing_rate(rec, sensor: int) -> np.ndarray:
    """The angular velocity (rad/s, T) of a leg-worn sensor about its principal axis (the
    leg's swing axis: the first right singular vector of the centred gyroscope samples), on a
    uniform grid at :data:`SIGNAL_RATE_HZ`; empty for a recording under two samples of it."""
    t = np.arange(rec.times[0], rec.times[-1], 1.0 / SIGNAL_RATE_HZ)
    if len(t) < 2:
        return np.zeros(0)
    gyro = resample_linear(rec.times, rec.gyro[:, sensor], t)
    gyro = gyro - gyro.mean(axis=0)
    _, _, vt = np.linalg.svd(gyro, full_matrices=False)
    return gyro @ vt[0]


def signal_cadence(rec, sensor: int = 0, stride_hz: tuple[float, float] = (0.5, 1.8)) -> float:
    """Cadence (steps/min) from the raw signal of a leg-worn sensor, independent of any
    reconstruction.

    The angular velocity about its principal axis (the leg's swing axis) repeats once per
    stride, with a strong second harmonic (two steps per stride, two knee flexions per
    cycle). With Welch's power spectral density ``P`` (16 s segments), the stride frequency is
    the ``f`` within ``stride_hz`` (walking and running strides) that maximizes
    ``P(f) + P(2 f)`` (a two-harmonic sum, so that neither a dominant fundamental nor a
    dominant harmonic is mistaken for the other); one stride has two steps.

    Parameters
    ----------
    rec : Recording (any sampling; resampled to 50 Hz internally).
    sensor : index of the sensor; it must ride on a leg (one swing per stride).
    """
    return _rate_cadence(_swing_rate(rec, sensor), stride_hz)


def _rate_cadence(rate: np.ndarray, stride_hz: tuple[float, float]) -> float:
    """:func:`signal_cadence` of a swing rate from :func:`_swing_rate`."""
    if len(rate) < 2:
        return math.nan
    return _stride_cadence(rate, SIGNAL_RATE_HZ, stride_hz, harmonics=(1, 2))


def signal_swing(rec, sensor: int = 0, stride_hz: tuple[float, float] = (0.5, 1.8)) -> float:
    """Degrees a leg-worn sensor turns through in one stride about the leg's swing axis, from
    its raw gyroscope, independent of any reconstruction: the rate about the principal axis
    (as :func:`signal_cadence` reads it) integrated, then :func:`_stride_range` at the
    signal's own stride frequency. A sensor on the shank gives the shank's swing, which
    :func:`shank_swings` measures on a motion: on virtual walks the two agree
    (``benchmarks/shin_stride.py``). NaN under two strides."""
    return signal_rhythm(rec, sensor, stride_hz)[1]


def signal_rhythm(rec, sensor: int = 0, stride_hz: tuple[float, float] = (0.5, 1.8)
                  ) -> tuple[float, float]:
    """:func:`signal_cadence` and :func:`signal_swing` from one reading of the swing rate."""
    rate = _swing_rate(rec, sensor)
    cadence = _rate_cadence(rate, stride_hz)
    if not math.isfinite(cadence):
        return cadence, math.nan
    angle = np.cumsum(rate) / SIGNAL_RATE_HZ
    return cadence, math.degrees(_stride_range(angle, SIGNAL_RATE_HZ, cadence / 120.0))


def shank_swings(motion: Motion, stride_hz: tuple[float, float] = (0.5, 1.8)
                 ) -> dict[str, float]:
    """Degrees each shank (knee to ankle; ``{"left": ..., "right": ...}``) turns through in
    one stride in the sagittal plane: its pitch against the vertical along the heading,
    :func:`_stride_range` at the motion's rhythm (:func:`motion_cadence`). What
    :func:`signal_swing` reads from a shank sensor. NaN under two strides."""
    p = motion.part_positions(["pelvis", "left_hip", "right_hip", "left_ankle", "right_ankle",
                               "left_knee", "right_knee"])
    cadence = _rhythm_cadence(p[:, :5], motion.fps, stride_hz)
    if not math.isfinite(cadence):
        return dict.fromkeys(FEET, math.nan)
    theta = heading_angle(p[:, 1], p[:, 2], 0.1 * motion.fps)
    out = {}
    for side, ankle, knee in zip(FEET, (3, 4), (5, 6)):
        shank = p[:, ankle] - p[:, knee]
        ahead = shank[:, 0] * np.sin(theta) + shank[:, 2] * np.cos(theta)
        pitch = np.arctan2(ahead, -shank[:, 1])
        out[side] = math.degrees(_stride_range(pitch, motion.fps, cadence / 120.0))
    return out


def _stride_range(angle: np.ndarray, rate: float, stride_f: float) -> float:
    """The median peak-to-peak of ``angle`` (T,) over consecutive windows of one stride
    (``stride_f`` Hz), after a zero-phase high-pass at 0.4 ``stride_f`` (2nd-order
    Butterworth): it removes a gyroscope bias's drift and slow changes of posture and keeps
    the stride's fundamental within 3 %. NaN under two strides."""
    n = round(rate / stride_f)
    if len(angle) < 2 * n or n < 2:
        return math.nan
    sos = butter(2, 0.4 * stride_f / (rate / 2.0), "highpass", output="sos")
    x = sosfiltfilt(sos, angle)
    return float(np.median([np.ptp(x[i:i + n]) for i in range(0, len(x) - n + 1, n)]))


def _stride_cadence(x: np.ndarray, rate: float, stride_hz: tuple[float, float],
                    harmonics: tuple[int, ...] = (1,)) -> float:
    """2 x 60 x the stride frequency of a signal x (T,) sampled at ``rate``: the f within
    ``stride_hz`` maximizing Welch's ``sum_k P(k f)`` over ``harmonics`` (16 s segments,
    clips shorter than that are one segment; zero-padded to 0.01 Hz bins so that short clips
    are not read off a coarse grid).

    A harmonic sum ties with its own subharmonic (``P(f/2) + P(f)``) whenever the signal has
    no power at ``2 f``, and the tie goes to the lower frequency: use ``harmonics=(1, 2)`` only
    for signals with a strong second harmonic (a leg's gyroscope), ``(1,)`` otherwise."""
    if len(x) < 2 * rate / stride_hz[0]:
        return math.nan  # less than two strides
    nperseg = min(len(x), int(16 * rate))
    nfft = max(nperseg, 1 << math.ceil(math.log2(100.0 * rate)))
    f, p = welch(x - x.mean(), fs=rate, nperseg=nperseg, nfft=nfft)
    cand = np.linspace(stride_hz[0], stride_hz[1], 521)
    score = sum(np.interp(k * cand, f, p) for k in harmonics)
    return float(2 * 60.0 * cand[np.argmax(score)])


def motion_cadence(motion: Motion, stride_hz: tuple[float, float] = (0.5, 1.8)) -> float:
    """Cadence (steps/min) from the rhythm of a motion rather than from detected strikes: the
    stride frequency (see :func:`signal_cadence`) of how far the right ankle is ahead of the
    left along the heading, which swings once per stride. Unlike the strike count it does
    not depend on the contact detector, which jitter in a reconstruction can fool into
    extra strikes. NaN for motions shorter than two slow strides (4 s).

    That difference changes sign every step (half-wave antisymmetric), so its spectrum holds
    the stride frequency and its odd harmonics only: the stride is the fundamental's peak (a
    ``P(f) + P(2 f)`` score would tie with ``f / 2`` and halve the cadence)."""
    return _rhythm_cadence(motion.part_positions(["pelvis", "left_hip", "right_hip",
                                                  "left_ankle", "right_ankle"]),
                           motion.fps, stride_hz)


def _rhythm_cadence(pos: np.ndarray, fps: float, stride_hz: tuple[float, float]) -> float:
    """:func:`motion_cadence` from the positions (T, 5, 3) of the pelvis, left and right hip,
    left and right ankle."""
    theta = heading_angle(pos[:, 1], pos[:, 2], 0.1 * fps)
    ahead = forward_difference(pos[:, 4], pos[:, 3], pos[:, 0], theta)
    return _stride_cadence(ahead, fps, stride_hz, harmonics=(1,))


def plausibility(motion: Motion, contacts: dict[str, np.ndarray] | None = None
                 ) -> dict[str, float]:
    """Checks of a reconstruction that need no ground truth.

    Returns
    -------
    dict: ``finite`` (1.0 when every rotation and position is finite), knee flexion
    ``knee_min_deg``/``knee_max_deg`` (both legs, limits :data:`KNEE_LIMITS_DEG`), hip angle
    ``hip_max_deg`` (limit :data:`HIP_LIMITS_DEG`), ``knee_out_of_range_pct`` and
    ``hip_out_of_range_pct`` (frames outside the limits), ``foot_skate_cm_s`` (mean horizontal
    speed of feet while the reconstruction's own contacts say they are down, see
    :func:`imuloco.measures.metrics.foot_skate`), ``contact_pct`` (frames with a foot down)
    and ``left_shank_swing_deg`` / ``right_shank_swing_deg`` (:func:`shank_swings`: in a
    walk both shanks swing alike, and a shank sensor's own swing, :func:`signal_swing`, says
    how far its leg's should).

    ``contacts``: the motion's :func:`imuloco.phases.foot_contacts` when already found (a
    :class:`~imuloco.phases.gait.GaitPhases`' ``contacts``).
    """
    pos = motion.positions()
    finite = bool(np.all(np.isfinite(pos)) and np.all(np.isfinite(motion.rotations)))
    knee = np.concatenate([knee_flexion(motion, s) for s in FEET])
    hip = np.concatenate([hip_angle(motion, s) for s in FEET])
    contacts = foot_contacts(motion) if contacts is None else contacts
    down = contacts["left_foot"] | contacts["right_foot"]
    out = lambda a, lim: 100.0 * float(np.mean((a < lim[0] - 1e-6) | (a > lim[1])))
    return {
        "finite": float(finite),
        "knee_min_deg": float(knee.min()), "knee_max_deg": float(knee.max()),
        "knee_out_of_range_pct": out(knee, KNEE_LIMITS_DEG),
        "hip_max_deg": float(hip.max()), "hip_out_of_range_pct": out(hip, HIP_LIMITS_DEG),
        "foot_skate_cm_s": foot_skate(motion, motion, contacts),
        "contact_pct": 100.0 * float(np.mean(down)),
        **{f"{side}_shank_swing_deg": v for side, v in shank_swings(motion).items()},
    }


@dataclass(frozen=True)
class Plausibility:
    """The checks of :func:`plausibility` (its keys, in order) as a report carries them;
    :meth:`to_json` rounds them (None for NaN)."""

    finite: float
    knee_min_deg: float
    knee_max_deg: float
    knee_out_of_range_pct: float
    hip_max_deg: float
    hip_out_of_range_pct: float
    foot_skate_cm_s: float
    contact_pct: float
    left_shank_swing_deg: float
    right_shank_swing_deg: float

    @classmethod
    def of(cls, motion: Motion, contacts: dict[str, np.ndarray] | None = None
           ) -> Plausibility:
        """:func:`plausibility` of ``motion`` (``contacts``: its foot contacts if known)."""
        return cls(**plausibility(motion, contacts))

    def to_dict(self) -> dict[str, float]:
        """The checks by name, as :func:`plausibility` returns them."""
        return asdict(self)

    def to_json(self) -> dict[str, Any]:
        """JSON-ready: rounded to 4 decimals, NaN as None (:func:`to_json`)."""
        return to_json(self.to_dict())
