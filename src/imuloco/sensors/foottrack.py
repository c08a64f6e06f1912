"""A foot sensor's swings and path, and the level frame it walks in.

The foot swings while the gyroscope norm's 50 ms window maximum exceeds 102 deg/s (SWING_DPS)
for at least 0.2 s, and the rotation about horizontal axes alone does for 0.2 s of it
(:func:`swings`; a pivot about the vertical with the foot down is part of a stance); between two
swings is one stance, and its stillest moment the foot's rest. A zero-velocity-update Kalman
filter with Rauch-Tung-Striebel smoothing (gaitmap's ``RtsKalman``) gives the foot's 3-D path,
with ``RtsKalman``'s default ZUPTs (the gyroscope's norm under 34 deg/s over 50 ms) or-ed with
one at each stance's stillest moment: some walkers' feet never get under 34 deg/s (their stance
minimum is 40-60 deg/s). Steps too slow for the swing threshold (a first step from standing, a
last one to a stop) are then read off the path (:func:`slow_swings`): a movement between two
rests that carries the foot farther than the shortest stride.

:func:`foot_track` also finds how the sensor sits on the shoe, in any orientation: gravity at
rest gives up (gaitmap's ``align_dataset_to_gravity``), and the strides' displacement seen from
the sensor at rest gives forward. Both the foot's gait (:mod:`imuloco.measures.sensorgait`)
and the foot's sensor-to-segment calibration (:mod:`imuloco.sensors.calibration`) read it.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from functools import lru_cache
from importlib import import_module
from typing import TYPE_CHECKING

import numpy as np
from scipy.ndimage import maximum_filter1d
from scipy.spatial.transform import Rotation

from imuloco.errors import MissingExtraError
from imuloco.ops.filters import resample_uniform
from imuloco.phases.contacts import runs
from imuloco.sensors.strapdown import anchored_path

if TYPE_CHECKING:
    import pandas as pd

ZUPT_WINDOW_S, ZUPT_GYRO_DPS = 0.05, 34.0  # gaitmap RtsKalman's default ZUPT detector
# the shortest swing: ~0.3 s even in sprinting (about 40 % of a 0.7 s stride; Novacheck 1998,
# The biomechanics of running, Gait & Posture 7); 0.2 s leaves a margin
SHORTEST_SWING_S = 0.3
MIN_SWING_S = 0.2  # fewer and no stride length or cadence is defined
# The foot swings while the gyroscope norm's 50 ms window maximum exceeds this for at least
# MIN_SWING_S (gaps within a swing bridged, see _bridged): three times the ZUPT detector's
# still threshold, far under the foot's mid-swing angular velocity of several hundred deg/s.
SWING_DPS = 3 * ZUPT_GYRO_DPS
# A step from standing or to a stop can be too slow for SWING_DPS (peaks of 110-130 deg/s for
# about 0.1 s on ipol-gait's first and closing steps): it counts as a swing when the foot leaves
# the ZUPT detector's rest for MIN_SWING_S between two rests and its ZUPT path moves it farther
# on the floor than the shortest stride (0.15 m; Kluge et al. 2021, Mobilise-D's stride
# definition, also mobgap's ``StrideSelection``).
MIN_STRIDE_M = 0.15


def _runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Starts and stops (exclusive) of the True runs of a 1-D mask."""
    starts, stops, vals = runs(mask)
    return starts[vals], stops[vals]


def _gaitmap():
    try:
        import gaitmap  # noqa: F401  (the [gait] extra: is it installed?)
    except ImportError as e:
        raise MissingExtraError("foot-sensor gait", f"gaitmap ({e})", "gait") from None


def _bridged(starts: np.ndarray, stops: np.ndarray, max_gap: int, min_length: int,
             whole: int) -> tuple[np.ndarray, np.ndarray]:
    """Runs (sample starts, exclusive stops) joined across gaps of at most ``max_gap``, then
    those shorter than ``min_length`` dropped.

    A gap between two runs of ``whole`` samples or more (each as long as a swing) is never
    bridged: a foot swings once per stride, so the dip between them is a stance, however
    brief (a jogging foot's gyroscope stays under the threshold for 10-65 ms only). Shorter
    runs are pieces of a swing (a push-off before toe off, the foot's slap after heel strike)
    and join the run after them first: the push-off belongs to the swing it starts.
    """
    out: list[list[int]] = []
    for a, b in zip(starts[::-1].tolist(), stops[::-1].tolist()):
        if out and out[-1][0] - b <= max_gap and min(b - a, out[-1][1] - out[-1][0]) < whole:
            out[-1][0] = a
        else:
            out.append([a, b])
    kept = np.array([r for r in out[::-1] if r[1] - r[0] >= min_length], int).reshape(-1, 2)
    return kept[:, 0], kept[:, 1]


def _energy(gyro_dps: np.ndarray, rate: float) -> np.ndarray:
    """The gyroscope norm's ZUPT-window maximum (deg/s), the ZUPT detector's measure."""
    return maximum_filter1d(np.linalg.norm(gyro_dps, axis=1), max(1, round(ZUPT_WINDOW_S * rate)))


def _lifted(gyro_dps: np.ndarray, rate: float) -> np.ndarray:
    """Where the foot turns about a horizontal axis faster than a swing's threshold: the
    ZUPT-window maximum of the gyroscope's x-y norm (z up at rest) over SWING_DPS.

    A swing lifts and pitches the foot; a pivot on the floor turns it about the vertical with
    the foot down. Swing detectors read the foot's or shank's sagittal angular velocity for
    that reason (Aminian et al. 2002, Salarian et al. 2004, gaitmap's Rampp event detection).
    """
    return _energy(gyro_dps[:, :2], rate) > SWING_DPS


def _moments(energy: np.ndarray, starts: np.ndarray, stops: np.ndarray) -> np.ndarray:
    """The stillest sample before the first swing, between two swings and after the last."""
    bounds = np.concatenate([[0], starts, [len(energy)]])
    lows = np.concatenate([[0], stops, [len(energy)]])
    return np.array([lo + int(np.argmin(energy[lo:hi])) for lo, hi in
                     zip(lows[:-1], bounds[1:])], int)


def _swing_runs(energy: np.ndarray, lifted: np.ndarray, rate: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """Starts and exclusive stops (samples) of the swings: runs of ``energy`` over SWING_DPS
    in which the foot is ``lifted`` (:func:`_lifted`) for at least MIN_SWING_S; a run that
    only turns the foot about the vertical is a pivot on the floor, part of a stance."""
    above = energy > SWING_DPS
    above[[0, -1]] = False  # a stance (however short) before the first and after the last
    window = max(1, round(ZUPT_WINDOW_S * rate))
    starts, stops = _bridged(*_runs(above), window, round(MIN_SWING_S * rate),
                             round(SHORTEST_SWING_S * rate))
    keep = np.array([lifted[a:b].sum() >= round(MIN_SWING_S * rate)
                     for a, b in zip(starts, stops)], bool)
    return starts[keep], stops[keep]


def _fast_swings(gyro_dps: np.ndarray, rate: float
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The ZUPT detector's measure (:func:`_energy`) and the swings' starts and exclusive
    stops (:func:`_swing_runs`)."""
    energy = _energy(gyro_dps, rate)
    return (energy, *_swing_runs(energy, _lifted(gyro_dps, rate), rate))


def swings(gyro_dps: np.ndarray, rate: float) -> tuple[np.ndarray, np.ndarray]:
    """The foot's swings and the stillest moment of each stance around them.

    gyro_dps : ndarray, shape (T, 3), deg/s on a uniform grid at ``rate`` Hz, z up at rest.

    Returns ``starts`` (K,), the samples where the swings start, and ``moments`` (K + 1,):
    the minimum of the gyroscope norm's 50 ms window maximum (the ZUPT detector's measure)
    before the first swing, between two swings and after the last one.
    """
    energy, starts, stops = _fast_swings(gyro_dps, rate)
    return starts, _moments(energy, starts, stops)


def slow_swings(gyro_dps: np.ndarray, rate: float, path: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`swings` with the steps too slow for them added (see MIN_STRIDE_M).

    path : ndarray (T, 3), the foot's ZUPT path on the same grid, metres, z up.

    A slow step is a run of at least MIN_SWING_S over the ZUPT threshold (gaps of one window
    bridged) that holds no faster swing and lies between two rests, across which the path
    moves more than MIN_STRIDE_M on the floor (from the stillest moment of the rest before to
    that of the rest after).
    """
    return _with_slow_swings(*_fast_swings(gyro_dps, rate), path, rate)


def _with_slow_swings(energy: np.ndarray, starts: np.ndarray, stops: np.ndarray,
                      path: np.ndarray, rate: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`slow_swings` from :func:`_fast_swings`' output (computed once per track)."""
    moving = energy > ZUPT_GYRO_DPS
    for a, b in zip(starts, stops):
        moving[a:b] = True
    window = max(1, round(ZUPT_WINDOW_S * rate))
    m_starts, m_stops = _bridged(*_runs(moving), window, 1, len(energy))
    new_starts, new_stops = [], []
    for i, (a, b) in enumerate(zip(m_starts.tolist(), m_stops.tolist())):
        if (b - a < round(MIN_SWING_S * rate) or a == 0 or b == len(energy)
                or np.any((starts >= a) & (starts < b))):
            continue
        lo = int(m_stops[i - 1]) if i else 0
        hi = int(m_starts[i + 1]) if i + 1 < len(m_starts) else len(energy)
        rest_before = lo + int(np.argmin(energy[lo:a]))
        rest_after = b + int(np.argmin(energy[b:hi]))
        if np.linalg.norm(path[rest_after, :2] - path[rest_before, :2]) > MIN_STRIDE_M:
            new_starts.append(a)
            new_stops.append(b)
    starts = np.concatenate([starts, np.asarray(new_starts, int)])
    stops = np.concatenate([stops, np.asarray(new_stops, int)])
    order = np.argsort(starts)
    return starts[order], _moments(energy, starts[order], stops[order])


def _zupt_detector(mv: np.ndarray):
    """``RtsKalman``'s default ZUPT detector or-ed with one ZUPT at each stance's stillest moment
    ``mv`` (samples), and the stride list of ``min_vel`` events the latter reads."""
    import pandas as pd  # the [gait] extra's (gaitmap's, and pandas with it)
    from gaitmap.zupt_detection import (
        ComboZuptDetector,
        NormZuptDetector,
        StrideEventZuptDetector,
    )

    strides = pd.DataFrame({"s_id": np.arange(max(len(mv) - 1, 0)), "start": mv[:-1],
                            "end": mv[1:], "min_vel": mv[:-1]}).set_index("s_id")
    norm = NormZuptDetector(window_length_s=ZUPT_WINDOW_S, metric="maximum",
                            inactive_signal_threshold=ZUPT_GYRO_DPS)  # RtsKalman's default
    combo = ComboZuptDetector([("norm", norm), ("stance", StrideEventZuptDetector(
        half_region_size_s=ZUPT_WINDOW_S / 2))], operation="or")
    return combo, strides


class NoWalking(ValueError):
    """The recording shows no walking a foot track can be built from (the message says why)."""


@dataclass
class FootTrack:
    """A foot sensor's walk, on a uniform grid.

    Attributes
    ----------
    rate : Hz of the grid; ``times`` (T,) its instants, seconds.
    level : DataFrame (T, 6), ``acc_x..gyr_z`` in m/s² and deg/s in the level frame: x
        forward (the walking direction), y left, z up (gaitmap's foot sensor frame).
    rotation : ndarray (4,), quaternion x, y, z, w from the sensor's axes to the level frame.
    starts : ndarray (K,), samples where the swings start; ``rest`` (K + 1,) the stances'
        stillest moments (:func:`slow_swings`).
    path, orientation : ndarray (T, 3) metres (z up, x and y on the floor, heading of the
        first sample) and (T, 4), the foot's ZUPT trajectory.
    """

    rate: float
    times: np.ndarray
    level: pd.DataFrame
    rotation: np.ndarray
    starts: np.ndarray
    rest: np.ndarray
    path: np.ndarray
    orientation: np.ndarray


def foot_track(times: np.ndarray, acc: np.ndarray, gyro: np.ndarray) -> FootTrack:
    """The foot's swings, path and level frame (module docstring); :class:`NoWalking` when the
    recording has none.

    times : ndarray (T,), seconds; acc, gyro : ndarray (T, 3), m/s² (+9.81 up at rest) and
    rad/s, in any sensor axes.

    The last few tracks are kept, keyed by the signals' bytes: ``reconstruct`` calibrates a
    shoe sensor and then measures its gait from the same signals, and the ZUPT filter takes
    about 5 s of CPU for 10 minutes of walking. Callers must not modify the track's arrays.
    """
    t, a, g = (np.ascontiguousarray(v, dtype=np.float64) for v in (times, acc, gyro))
    return _track(t.tobytes(), a.tobytes(), g.tobytes())


# gaitmap's numba kernels the track runs that gaitmap compiles without numba's on-disk cache
# and that numba can cache: (module, function). Its RTS Kalman filter
# (``_rts_kalman_update_series``, ~40 CPU s of a 60 s shoe walk's reconstruction, compiled
# afresh in every process) cannot be: it takes its motion model as a function argument, and
# numba's cache misses on such signatures in every new process (numba issue #9237); only a
# change in gaitmap would keep it (docs/results/speed/reconstruct.md).
GAITMAP_KERNELS = (("gaitmap.utils.array_handling", "_solve_overlap"),)


@lru_cache(maxsize=1)
def _cache_gaitmap_kernels() -> None:
    """Turn numba's on-disk cache on for :data:`GAITMAP_KERNELS` (as ``cache=True`` would:
    beside gaitmap's sources, else numba's per-user cache folder); a kernel a gaitmap version
    does not have, or names differently, is left as it is."""
    for module, name in GAITMAP_KERNELS:
        try:
            kernel = getattr(import_module(module), name)
        except (ImportError, AttributeError):
            continue
        if hasattr(kernel, "enable_caching"):  # a numba dispatcher
            kernel.enable_caching()


@lru_cache(maxsize=4)
def _track(times_b: bytes, acc_b: bytes, gyro_b: bytes) -> FootTrack:
    """:func:`foot_track` of signals given as float64 bytes."""
    _gaitmap()  # before pandas, which the [gait] extra brings too
    _cache_gaitmap_kernels()
    # the [gait] extra's (gaitmap, and pandas, which it brings): imported when used
    import pandas as pd
    from gaitmap.preprocessing.sensor_alignment import align_dataset_to_gravity
    from gaitmap.trajectory_reconstruction import RtsKalman

    times = np.frombuffer(times_b)
    acc, gyro = np.frombuffer(acc_b).reshape(-1, 3), np.frombuffer(gyro_b).reshape(-1, 3)
    if len(times) < 2 or times[-1] - times[0] < 2.0:
        raise NoWalking("the recording is shorter than 2 s, less than one stride")
    rate = (len(times) - 1) / (times[-1] - times[0])  # the mean rate
    x = resample_uniform(times, np.concatenate([acc, np.degrees(gyro)], axis=1), rate)
    cols = ["acc_x", "acc_y", "acc_z", "gyr_x", "gyr_y", "gyr_z"]
    raw = pd.DataFrame(x, columns=cols)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # gaitmap warns when few still windows are found
        # gravity from gaitmap's defaults (standing: 0.7 s under 2.5 deg/s), else from the
        # ZUPT detector's foot-flat moments (50 ms under 34 deg/s), else from a foot never
        # that still: its stances' stillest moments (50 ms under SWING_DPS)
        for still in ({}, {"window_length_s": ZUPT_WINDOW_S, "static_signal_th": ZUPT_GYRO_DPS},
                      {"window_length_s": ZUPT_WINDOW_S, "static_signal_th": SWING_DPS}):
            try:
                data = align_dataset_to_gravity(raw, rate, **still)
                break
            except ValueError:
                continue
        else:
            raise NoWalking("the foot is never still: no stance, so no walking")
        fast = _fast_swings(data[cols[3:]].to_numpy(), rate)
        starts, rest = fast[1], _moments(*fast)
        if len(starts) < 2:
            raise NoWalking(f"{len(starts)} swing(s) found: no walking (a foot sensor needs at "
                            "least 2 strides)")
        zupt, moments = _zupt_detector(rest)
        kalman = RtsKalman(zupt_detector=zupt).estimate(data, sampling_rate_hz=rate,
                                                        stride_event_list=moments)
    pos = kalman.position_.to_numpy()[1:]  # gaitmap prepends the initial state
    ori = kalman.orientation_.to_numpy()[1:]
    # the slow steps are read off the path; the filter needs no second pass, since they lie
    # between rests under the ZUPT threshold, where the norm detector already holds the foot
    starts, rest = _with_slow_swings(*fast, pos, rate)
    # the sensor's forward axis: stride displacements seen from the sensor at rest, gravity
    # already along its z (a fixed mounting yaw, the median over strides)
    disp = np.diff(pos[rest], axis=0)
    local = Rotation.from_quat(ori[rest[:-1]]).inv().apply(disp)
    keep = np.linalg.norm(disp[:, :2], axis=1) > 0.2  # strides, not shuffles (0.2 m)
    if not keep.any():
        raise NoWalking("the foot never moved more than 0.2 m between two stances: no walking")
    yaw = float(np.median(np.arctan2(local[keep, 1], local[keep, 0])))
    turn = Rotation.from_euler("z", -yaw)
    level = data.copy()
    level[cols[:3]] = turn.apply(data[cols[:3]].to_numpy())
    level[cols[3:]] = turn.apply(data[cols[3:]].to_numpy())
    # gaitmap rotates the data without returning its rotation: recover it from both copies
    # (exact, a rotation maps every sample the same way)
    grav, _ = Rotation.align_vectors(data.to_numpy().reshape(-1, 3), x.reshape(-1, 3))
    t = times[0] + np.arange(len(data)) / rate
    return FootTrack(rate, t, level, (turn * grav).as_quat(), starts, rest, pos, ori)


def anchored_track(track: FootTrack) -> tuple[np.ndarray, np.ndarray]:
    """The foot's path (T, 3) metres (z up, the level frame's axes) integrated between its
    rests with zero-velocity updates (:func:`imuloco.sensors.strapdown.anchored_path`, lever
    arm 0; still wherever the ZUPT detector holds the foot), and those rests (K,): the stances'
    stillest moments still enough for a stance (not the end of a cut swing).

    The one foot path of imuloco: the ``foot-zupt`` path estimator the animation follows and
    the foot's gait (:func:`imuloco.measures.sensorgait.foot_gait`) read it. On virtual feet
    its distance is off by 1.7-2.8 % where ``track.path`` (gaitmap's RtsKalman) is off by
    9-18 % (its orientation goes astray on some simulated feet; docs/results/path/)."""
    lev = track.level.to_numpy()
    gyro = np.radians(lev[:, 3:])
    energy = maximum_filter1d(np.linalg.norm(gyro, axis=1),
                              max(1, round(ZUPT_WINDOW_S * track.rate)))
    rest = np.asarray(track.rest[energy[track.rest] < np.radians(SWING_DPS)], int)
    if len(rest) < 2:
        return track.path, rest
    path, _, _ = anchored_path(lev[:, :3], gyro, track.rate, rest, np.zeros(3),
                               energy < np.radians(ZUPT_GYRO_DPS))
    return path, rest
