"""Sensor error models and their presets.

Levels (per recording unless noted), with their sources:

``phone`` — a mid-range smartphone IMU (Bosch BMI160 / ST LSM6DS3 class) used as a sport band:
  accelerometer white noise 0.03 m/s^2 rms at 100 Hz (datasheet ~180-300 ug/sqrt(Hz) over a 50 Hz
  band, raised for handling vibration), gyroscope white noise 0.005 rad/s rms (0.007-0.01
  dps/sqrt(Hz) over 50 Hz, plus quantisation); constant biases of 0.1 m/s^2 and 0.01 rad/s (1
  sigma; typical post-factory-calibration offsets of +-40 mg and +-1 deg/s); the phone strapped up
  to 10 degrees off and a few cm (up to 3) from the intended place; timestamp jitter of 2 ms rms
  around a nominal 100 Hz (Android sensor events are not evenly spaced; at higher rates it
  shrinks with the period, :data:`JITTER_RATE`); 0.5 % of samples dropped
  in bursts; saturation at +-16 g and +-2000 deg/s (the largest full-scale ranges of such parts).
``imu`` — a dedicated research IMU (Xsens MTi / Movella DOT class): 0.005 m/s^2 and 0.001 rad/s
  white noise, biases of 0.02 m/s^2 and 0.002 rad/s, 2 degrees and 1 cm placement error,
  hardware-timed samples, no drops, the same saturation.
``clean`` — none of these.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imuloco.errors import UnknownNameError

G = 9.81
# the rate at which a preset's jitter_s holds; above it the jitter is that fraction of the
# sample period (2 ms at 100 Hz: 20 us at 10 kHz), so that a simulated log stays a log of its
# rate (2 ms at 10 kHz reordered whole periods: median step 71 us, a rate the reader refuses).
# Every rate up to it (the simulations behind all results are at 100 Hz or less) is unchanged.
JITTER_RATE = 100.0


@dataclass(frozen=True)
class NoiseModel:
    """Error levels of one sensor class (see the module docstring for each preset's sources)."""

    name: str
    acc_noise: float = 0.0         # white noise, m/s^2 rms
    gyro_noise: float = 0.0        # white noise, rad/s rms
    acc_bias: float = 0.0          # constant bias per recording and axis, m/s^2 (1 sigma)
    gyro_bias: float = 0.0         # rad/s (1 sigma)
    misalignment_deg: float = 0.0  # largest rotation of the sensor on the segment
    offset_m: float = 0.0          # largest displacement from the intended place
    jitter_s: float = 0.0          # timestamp jitter, seconds rms
    drop_rate: float = 0.0         # fraction of samples lost
    acc_range: float = 16 * G      # saturation, m/s^2
    gyro_range: float = np.deg2rad(2000.0)  # saturation, rad/s


NOISE_PRESETS: dict[str, NoiseModel] = {
    "clean": NoiseModel("clean", acc_range=np.inf, gyro_range=np.inf),
    "phone": NoiseModel("phone", 0.03, 0.005, 0.1, 0.01, 10.0, 0.03, 0.002, 0.005),
    "imu": NoiseModel("imu", 0.005, 0.001, 0.02, 0.002, 2.0, 0.01, 0.0, 0.0),
}


def get_noise(name: str | NoiseModel) -> NoiseModel:
    if isinstance(name, NoiseModel):
        return name
    if name not in NOISE_PRESETS:
        raise UnknownNameError(f"unknown noise preset {name!r}; presets: {sorted(NOISE_PRESETS)}")
    return NOISE_PRESETS[name]


def random_misplacement(model: NoiseModel, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A rotation (quaternion, angle uniform up to ``misalignment_deg`` about a random axis) and
    an offset (uniform in a ball of radius ``offset_m``) for one strapping of the sensor."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    ang = np.deg2rad(model.misalignment_deg) * rng.uniform()
    rot = np.concatenate([axis * np.sin(ang / 2), [np.cos(ang / 2)]])
    direction = rng.normal(size=3)
    direction /= np.linalg.norm(direction)
    offset = direction * model.offset_m * rng.uniform() ** (1 / 3)
    return rot, offset


def sample_times(duration: float, rate: float, model: NoiseModel,
                 rng: np.random.Generator) -> np.ndarray:
    """Sample instants in [0, duration]: nominal ``rate`` with jitter (``jitter_s`` up to
    :data:`JITTER_RATE`, the same fraction of the period above it) and dropped bursts."""
    t = np.arange(0.0, duration + 1e-9, 1.0 / rate)
    if model.jitter_s > 0:
        jitter = model.jitter_s * min(1.0, JITTER_RATE / rate)
        t = t + rng.normal(0.0, jitter, len(t))
        t = np.sort(np.clip(t, 0.0, duration))
    if model.drop_rate > 0:
        # bursts of 1-5 samples starting at random so that on average drop_rate are lost
        starts = rng.uniform(size=len(t)) < model.drop_rate / 3.0
        keep = np.ones(len(t), bool)
        for s in np.flatnonzero(starts):
            keep[s:s + rng.integers(1, 6)] = False
        keep[[0, -1]] = True
        t = t[keep]
    return np.unique(t)


def corrupt(acc: np.ndarray, gyro: np.ndarray, model: NoiseModel,
            rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Add bias and white noise, then saturate. acc, gyro : (T, 3) -> (T, 3), (T, 3)."""
    acc = acc + rng.normal(0, model.acc_bias, 3) + rng.normal(0, model.acc_noise, acc.shape)
    gyro = gyro + rng.normal(0, model.gyro_bias, 3) + rng.normal(0, model.gyro_noise, gyro.shape)
    return (np.clip(acc, -model.acc_range, model.acc_range),
            np.clip(gyro, -model.gyro_range, model.gyro_range))
