"""Measurements of the live mode (``imuloco bench --live``): recovery after a sensor dropout,
and a loopback load test of the server under an abusive client.

Dropout recovery. One recording is streamed through :class:`LiveSession` twice: whole, and
with ``gap_s`` seconds of samples removed from ``gap_start`` on. The walker has *recovered* at
the first frame after the gap from which, for the rest of the compared window, the pose error
against the whole run's frame of the same number stays at or below ``threshold_cm``. The pose
error is the MPJPE of :func:`imuloco.evaluate.metrics.joint_errors` (joint positions relative
to the pelvis in the heading frame, all joints but the root, cm). The recovery time counts
stream seconds from the first sample after the gap, so it does not depend on the machine.
Where the walker stands is reported beside it: the horizontal distance between the two runs'
roots and the difference of their headings at the end of the window.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from imuloco.app.live.session import Frame, LiveSession


@dataclass
class Recovery:
    """How the walker came back after a dropout (see the module docstring).

    gap_start, gap_s : the dropout, seconds on the recording's clock and its length.
    recovery_s : stream seconds from the first sample after the gap until the pose error stays
        at or below ``threshold_cm`` (``inf``: not within the window).
    errors_cm : (K,) pose error of each compared frame after the gap; times_s : (K,) their
        times in seconds after the first sample after the gap.
    root_offset_m, heading_offset_deg : the runs' roots (horizontal distance) and headings
        apart at the last compared frame.
    """

    gap_start: float
    gap_s: float
    threshold_cm: float
    recovery_s: float
    errors_cm: np.ndarray
    times_s: np.ndarray
    root_offset_m: float
    heading_offset_deg: float

    def to_json(self) -> dict:
        d = asdict(self)
        d["errors_cm"] = np.round(self.errors_cm, 3).tolist()
        d["times_s"] = np.round(self.times_s, 4).tolist()
        return d


def _stream(method, times: np.ndarray, acc: np.ndarray, gyro: np.ndarray,
            calibrate_s: float) -> dict[int, Frame]:
    s = LiveSession(method, calibrate_s)
    return {f.index: f for i in range(len(times)) for f in s.push(times[i], acc[i], gyro[i])}


def dropout_recovery(method, times: np.ndarray, acc: np.ndarray, gyro: np.ndarray,
                     gap_start: float, gap_s: float = 1.0, threshold_cm: float = 1.0,
                     calibrate_s: float = 4.0, window_s: float = 2.0) -> Recovery:
    """Recovery after removing ``gap_s`` seconds of samples from ``gap_start`` on.

    Parameters
    ----------
    method : a fitted online method.
    times : ndarray, shape (N,), seconds; acc, gyro : ndarray, shape (N, S, 3), the phone's
        raw samples (m/s^2, rad/s) as :meth:`LiveSession.push` takes them.
    window_s : seconds after the gap compared (the recording must reach that far).
    """
    from imuloco.core.motion import Motion
    from imuloco.evaluate.metrics import heading_of, joint_errors

    keep = (times < gap_start) | (times >= gap_start + gap_s)
    whole = _stream(method, times, acc, gyro, calibrate_s)
    gapped = _stream(method, times[keep], acc[keep], gyro[keep], calibrate_s)
    resume = float(times[keep][np.searchsorted(times[keep], gap_start)])
    after = sorted(k for k, f in gapped.items() if k in whole and f.time >= resume
                   and f.time <= resume + window_s)
    if len(after) < 2 or gapped[after[-1]].time < resume + 0.9 * window_s:
        raise ValueError(f"the recording ends before {window_s} s after the gap")
    sk, fps = method.skeleton_, float(method.fps_)

    def motion(frames: dict[int, Frame]) -> Motion:
        return Motion(sk, np.stack([frames[k].rotations for k in after]),
                      np.stack([frames[k].root for k in after]), fps)

    a, b = motion(whole), motion(gapped)
    errors = joint_errors(a, b)[:, 1:].mean(axis=1) * 100.0
    t = np.array([gapped[k].time for k in after]) - resume
    over = np.flatnonzero(errors > threshold_cm)
    if len(over) == 0:
        recovery = float(t[0])
    elif over[-1] == len(t) - 1:
        recovery = float("inf")
    else:
        recovery = float(t[over[-1] + 1])
    heading = np.degrees(heading_of(a)[-1] - heading_of(b)[-1])
    return Recovery(gap_start, gap_s, threshold_cm, recovery, errors, t,
                    float(np.linalg.norm((a.root[-1] - b.root[-1])[[0, 2]])),
                    float((heading + 180.0) % 360.0 - 180.0))
