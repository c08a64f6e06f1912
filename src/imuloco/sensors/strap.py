"""A phone strapped on soft tissue: how it moves on the segment it is strapped to.

A phone on a strap is not fixed to the bone: it sits on skin and muscle that let it lag, ring
and roll. Modelled as the wobbling mass of soft-tissue artefact studies, a second-order system
between the segment and the phone (natural frequency ``freq_hz``, damping ratio ``damping``):

* **translation**: the phone follows the segment through
  ``H(s) = (2 z w s + w^2) / (s^2 + 2 z w s + w^2)`` (a mass on a spring and damper), applied
  to the specific force in the sensor frame: gravity passes unchanged, heel-strike impacts are
  damped, motion near ``freq_hz`` rings;
* **roll about the segment's long axis** (the sensor's y), the way a strapped phone turns
  around the shin: driven by the segment's angular acceleration about its medio-lateral axis
  (the sensor's x; a phone whose mass sits off the strap's line is swung round by it) through
  ``roll_gain * w^2 / (s^2 + 2 z w s + w^2)``; ``roll_gain`` is the static roll in radians per
  rad/s² (either sign: it depends on which side of the strap the phone's mass is).

Hand-written because no library models a worn sensor's soft tissue; the filtering is scipy's.
The virtual sensors of :mod:`imuloco.sensors.simulate` are rigid unless given a strap.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# Ranges of :func:`random_strap`: from a phone held tight (a stiff, damped mount ringing at
# 15 Hz, no roll) to one loose on a soft strap (2 Hz, lightly damped, rolling up to 0.003 rad
# per rad/s², ~0.25 rad at a walking shank's 80 rad/s² around toe off). An assumption: no
# study of strapped phones gives these figures.
FREQ_HZ = (2.0, 15.0)
DAMPING = (0.2, 0.8)
ROLL_GAIN = 0.003


@dataclass(frozen=True)
class Strap:
    """How one phone sits on its strap (module docstring)."""

    freq_hz: float
    damping: float
    roll_gain: float


def random_strap(rng: np.random.Generator) -> Strap:
    """A strap drawn from the ranges above: frequency log-uniform, damping and roll gain
    uniform."""
    return Strap(float(np.exp(rng.uniform(*np.log(FREQ_HZ)))), float(rng.uniform(*DAMPING)),
                 float(rng.uniform(-ROLL_GAIN, ROLL_GAIN)))


def _second_order(num: list[float], strap: Strap, rate: float, x: np.ndarray) -> np.ndarray:
    """``x`` (T, ...) on a uniform grid at ``rate`` Hz through ``num / (s^2 + 2 z w s + w^2)``
    (bilinear transform), started at rest at ``x[0]``."""
    from scipy.signal import bilinear, lfilter, lfilter_zi  # 0.8 s to import: only when worn

    w = 2 * np.pi * strap.freq_hz
    b, a = bilinear(num, [1.0, 2 * strap.damping * w, w * w], fs=rate)
    zi = lfilter_zi(b, a).reshape(-1, *([1] * (x.ndim - 1))) * x[:1]
    return lfilter(b, a, x, axis=0, zi=zi)[0]


def strapped(acc: np.ndarray, gyro: np.ndarray, rate: float, strap: Strap
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What the strapped phone reads where a rigid sensor reads ``acc`` and ``gyro``.

    acc, gyro : ndarray, shape (T, 3), m/s² and rad/s in the sensor frame (y along the
        segment, x medio-lateral), on a uniform grid at ``rate`` Hz.

    Returns
    -------
    acc, gyro (T, 3) of the phone, and its roll (T,) about y relative to the rigid sensor,
    radians.
    """
    w = 2 * np.pi * strap.freq_hz
    acc = _second_order([2 * strap.damping * w, w * w], strap, rate, acc)
    roll = (_second_order([strap.roll_gain * w * w], strap, rate,
                          np.gradient(gyro[:, 0], 1.0 / rate)) if strap.roll_gain
            else np.zeros(len(gyro)))
    c, s = np.cos(roll)[:, None], np.sin(roll)[:, None]

    def unroll(v: np.ndarray) -> np.ndarray:  # v seen from the phone turned by roll about y
        return np.concatenate([c * v[:, :1] - s * v[:, 2:], v[:, 1:2],
                               s * v[:, :1] + c * v[:, 2:]], axis=1)

    gyro = unroll(gyro)
    gyro[:, 1] += np.gradient(roll, 1.0 / rate)
    return unroll(acc), gyro, roll
