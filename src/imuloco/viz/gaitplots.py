"""Plots of a walk's gait for the reconstruction's summary (PNG): strides over time, left
against right, foot contacts and the predicted error.

Each function takes plain arrays or a report's JSON values (a stride is a dict with ``foot``,
``start_s``, ``duration_s``, ``length_m``, ``stance_s``, ``swing_s``, as
:data:`imuloco.measures.strides.STRIDE_FIELDS`), writes one file and returns its path; figures
are built as in :mod:`imuloco.viz.plots` (object API, Agg canvas).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from scipy.ndimage import median_filter

from imuloco.viz.plots import _figure, _save

FOOT_COLORS = {"left": "tab:blue", "right": "tab:red"}


def _column(strides: Sequence[dict], foot: str, key: str) -> np.ndarray:
    """One field of ``foot``'s strides as floats (None: NaN). -> shape (N,)"""
    return np.array([np.nan if s.get(key) is None else float(s[key])
                     for s in strides if s.get("foot") == foot], dtype=np.float64)


def _feet(strides: Sequence[dict]) -> list[str]:
    return [f for f in FOOT_COLORS if any(s.get("foot") == f for s in strides)]


def plot_strides(strides: Sequence[dict], path: str | Path, overwrite: bool = False) -> Path:
    """Stride length (m) and cadence (steps/min, 120 / stride duration) of every stride
    against its start time, per foot, with a running median over 9 strides."""
    fig = _figure(9, 4.8)
    top, bottom = fig.subplots(2, 1, sharex=True)
    for foot in _feet(strides):
        t = _column(strides, foot, "start_s")
        for ax, values in ((top, _column(strides, foot, "length_m")),
                           (bottom, 120.0 / _column(strides, foot, "duration_s"))):
            ax.plot(t, values, ".", ms=3, alpha=0.4, color=FOOT_COLORS[foot])
            ok = np.isfinite(values)
            if ok.sum() >= 9:
                ax.plot(t[ok], median_filter(values[ok], 9, mode="nearest"), lw=1.2,
                        color=FOOT_COLORS[foot], label=f"{foot} foot (median of 9)")
    cadence = 120.0 / np.array([s.get("duration_s") or np.nan for s in strides], dtype=float)
    if np.isfinite(cadence).sum() >= 2:  # 1st-99th percentile: a stray strike read 700/min
        low, high = np.nanpercentile(cadence, [1, 99])
        bottom.set_ylim(0.8 * low, 1.2 * high)
    top.set_ylabel("stride length (m)")
    bottom.set_ylabel("cadence (steps/min)")
    bottom.set_xlabel("time (s)")
    top.set_title("each stride (strike to strike of one foot)", fontsize=9)
    if top.get_legend_handles_labels()[0]:
        top.legend(loc="upper right", fontsize=7)
    return _save(fig, path, overwrite)


def plot_symmetry(strides: Sequence[dict], path: str | Path,
                  swing_deg: dict[str, float] | None = None,
                  signal_swing_deg: float | None = None, overwrite: bool = False) -> Path:
    """Left against right: stride length, stance and swing time (medians with their
    interquartile range over the strides) and, for a shank sensor, each reconstructed shank's
    swing beside the sensor's own (``signal_swing_deg``, model-free)."""
    fields = (("length_m", "stride length (m)"), ("stance_s", "stance (s)"),
              ("swing_s", "swing (s)"))
    panels = len(fields) + (swing_deg is not None)
    fig = _figure(2.6 * panels, 3.0)
    axes = np.atleast_1d(fig.subplots(1, panels))
    feet = list(FOOT_COLORS)
    for ax, (key, label) in zip(axes, fields):
        for i, foot in enumerate(feet):
            v = _column(strides, foot, key)
            v = v[np.isfinite(v)]
            if len(v):
                q1, med, q3 = np.percentile(v, [25, 50, 75])
                ax.bar(i, med, color=FOOT_COLORS[foot], alpha=0.7,
                       yerr=[[med - q1], [q3 - med]], capsize=4)
        ax.set_xticks(range(len(feet)), feet)
        ax.set_title(label, fontsize=9)
    if swing_deg is not None:
        ax = axes[-1]
        for i, foot in enumerate(feet):
            ax.bar(i, swing_deg.get(foot) or np.nan, color=FOOT_COLORS[foot], alpha=0.7)
        ax.set_xticks(range(len(feet)), feet)
        if signal_swing_deg is not None:
            ax.axhline(signal_swing_deg, color="k", ls="--", lw=1, label="sensor's own")
            ax.legend(loc="lower right", fontsize=7)
        ax.set_title("shank swing a stride (deg)", fontsize=9)
    return _save(fig, path, overwrite)


def plot_contacts(strides: Sequence[dict], path: str | Path, seconds: float = 20.0,
                  overwrite: bool = False) -> Path:
    """Each foot's stance (from its strike, ``stance_s`` long) and swing as bars over the
    first ``seconds`` of strides: the gait diagram of the walk's start."""
    fig = _figure(9, 2.2)
    ax = fig.subplots()
    feet = _feet(strides)
    t0 = min((s["start_s"] for s in strides), default=0.0)
    for row, foot in enumerate(feet):
        for s in strides:
            if s.get("foot") != foot or s["start_s"] > t0 + seconds or s.get("stance_s") is None:
                continue
            ax.broken_barh([(s["start_s"], s["stance_s"])], (row - 0.35, 0.7),
                           color=FOOT_COLORS[foot], alpha=0.8)
    ax.set_yticks(range(len(feet)), [f"{f} foot down" for f in feet], fontsize=8)
    ax.set_xlabel("time (s)")
    ax.set_title(f"foot contacts, the first {seconds:g} s of strides (gaps: swing)", fontsize=9)
    return _save(fig, path, overwrite)


def plot_predicted_error(error_m_per_s: Sequence[float | None], bin_s: float, path: str | Path,
                         segments: Sequence[Sequence[float]] = (),
                         overwrite: bool = False) -> Path:
    """The method's predicted rms joint position error over time (cm, means over ``bin_s``
    seconds) with its unreliable segments (``[start_s, end_s]``) shaded, against the scale
    lines a reader compares it with (5, 10 and 20 cm)."""
    err = np.array([np.nan if v is None else 100.0 * v for v in error_m_per_s])
    t = (np.arange(len(err)) + 0.5) * bin_s
    fig = _figure(9, 2.8)
    ax = fig.subplots()
    ax.plot(t, err, color="tab:orange", lw=1, label="predicted error")
    for k, (a, b) in enumerate(segments):
        ax.axvspan(a, b, color="tab:red", alpha=0.15, lw=0,
                   label="flagged unreliable" if k == 0 else None)
    for level in (5, 10, 20):
        ax.axhline(level, color="0.6", lw=0.6, ls=":")
    ax.set_ylim(0, max(25.0, float(np.nanmax(err)) * 1.1) if np.isfinite(err).any() else 25.0)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("rms joint error (cm)")
    ax.set_title("the model's predicted error (dotted: 5, 10, 20 cm)", fontsize=9)
    ax.legend(loc="upper right", fontsize=7)
    return _save(fig, path, overwrite)
