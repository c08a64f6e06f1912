"""Static plots (PNG): sensor signals, detected gait phases, reconstruction errors, the
body's path seen from above.

Figures are built with matplotlib's object API on the Agg canvas (no pyplot state, no
display). Every function writes one file and returns its path.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from imuloco.core.motion import Motion
from imuloco.core.recording import Recording
from imuloco.io.atomic import atomic_path, check_output
from imuloco.measures.metrics import joint_errors, rmse_per_frame
from imuloco.paths.base import BodyPath
from imuloco.phases.contacts import runs
from imuloco.phases.gait import GAIT8, GaitPhases


def _figure(width: float, height: float):
    import matplotlib  # the [viz] extra's

    matplotlib.use("Agg")
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _save(fig, path: str | Path, overwrite: bool) -> Path:
    path = Path(path)
    check_output(path, overwrite)
    with atomic_path(path) as tmp:
        fig.savefig(tmp)
    return path


def _shade_contacts(ax, phases: GaitPhases, foot: str, color: str) -> None:
    """Shade the frames where ``foot`` is down (times in seconds)."""
    starts, stops, vals = runs(phases.contacts[f"{foot}_foot"])
    for a, b in zip(starts[vals], stops[vals]):
        ax.axvspan(a / phases.fps, b / phases.fps, color=color, alpha=0.12, lw=0)


def plot_signals(rec: Recording, path: str | Path, phases: GaitPhases | None = None,
                 foot: str = "right", max_seconds: float | None = 20.0,
                 overwrite: bool = False) -> Path:
    """Accelerometer and gyroscope of every sensor over time, with ``foot``'s contact
    frames of ``phases`` (a reconstruction's or the ground truth's) shaded.

    max_seconds : only the first seconds (long recordings are unreadable whole).
    """
    keep = slice(None) if max_seconds is None else rec.times - rec.times[0] <= max_seconds
    t = rec.times[keep] - rec.times[0]
    fig = _figure(9, 2.2 * 2 * len(rec.placements))
    axes = fig.subplots(2 * len(rec.placements), 1, sharex=True, squeeze=False)[:, 0]
    for s, name in enumerate(rec.placements):
        for row, (values, label) in enumerate(((rec.acc, "specific force (m/s²)"),
                                               (rec.gyro, "angular velocity (rad/s)"))):
            ax = axes[2 * s + row]
            for k, axis in enumerate("xyz"):
                ax.plot(t, values[keep, s, k], lw=0.8, label=axis)
            ax.set_ylabel(label, fontsize=8)
            ax.set_title(f"{name} {'accelerometer' if row == 0 else 'gyroscope'}", fontsize=9)
            ax.legend(loc="upper right", fontsize=7, ncols=3)
            if phases is not None:
                _shade_contacts(ax, phases, foot, "tab:green")
    axes[-1].set_xlabel("time (s)" + (f"; shaded: {foot} foot down" if phases else ""))
    return _save(fig, path, overwrite)


def plot_phases(phases: GaitPhases, path: str | Path, max_seconds: float | None = 20.0,
                overwrite: bool = False) -> Path:
    """Heel/toe contacts of both feet, the 8 gait phases of the reference leg and the steps."""
    n = phases.num_frames if max_seconds is None else min(
        phases.num_frames, int(max_seconds * phases.fps) + 1)
    t = np.arange(n) / phases.fps
    fig = _figure(9, 3.6)
    top, bottom = fig.subplots(2, 1, sharex=True, height_ratios=[1, 1.2])
    rows = ("left_heel", "left_toe", "right_heel", "right_toe")
    for i, key in enumerate(rows):
        color = "tab:blue" if key.startswith("left") else "tab:red"
        top.fill_between(t, i, i + 0.8 * phases.contacts[key][:n], step="post", color=color,
                         alpha=0.7, lw=0)
    for foot, color in (("left", "tab:blue"), ("right", "tab:red")):
        strikes = phases.steps[foot][phases.steps[foot] < n] / phases.fps
        top.vlines(strikes, -0.3, len(rows), color=color, lw=0.6, ls=":")
    top.set_yticks(np.arange(len(rows)) + 0.4, [r.replace("_", " ") for r in rows], fontsize=8)
    top.set_title(f"foot contacts (dotted: strikes); cadence {phases.cadence_spm:.1f} steps/min",
                  fontsize=9)
    bottom.step(t, phases.phase[:n], where="post", color="k", lw=1)
    bottom.set_yticks(range(len(GAIT8)), list(GAIT8), fontsize=8)
    bottom.set_title(f"gait phase of the {phases.reference} leg (Mousas 2017 Table 1)", fontsize=9)
    bottom.set_xlabel("time (s)")
    return _save(fig, path, overwrite)


def plot_errors(gt: Motion, rec: Motion, path: str | Path, overwrite: bool = False,
                predicted_m: np.ndarray | None = None, unreliable: np.ndarray | None = None
                ) -> Path:
    """Mean position error per joint (bars) and the per-frame RMSE over time, cm, of a
    reconstruction against its ground truth (:mod:`imuloco.measures.metrics`).

    predicted_m : ndarray, shape (T,), optional: the method's predicted rms joint position
        error per frame, metres, drawn beside the actual one.
    unreliable : ndarray of bool, shape (T,), optional: frames the method flags, shaded."""
    err = joint_errors(gt, rec) * 100.0  # (T, J) cm
    per_joint = err[:, 1:].mean(axis=0)
    curve = rmse_per_frame(gt, rec)
    fig = _figure(9, 5.5)
    left, right = fig.subplots(2, 1, height_ratios=[1.2, 1])
    names = gt.skeleton.names[1:]
    left.bar(range(len(names)), per_joint, color="tab:purple")
    left.set_xticks(range(len(names)), names, rotation=60, ha="right", fontsize=7)
    left.set_ylabel("mean error (cm)")
    left.set_title("position error per joint (relative to the pelvis, heading frame)",
                   fontsize=9)
    title = f"per-frame RMSE over time (mean {curve.mean():.1f} cm)"
    right.plot(gt.times, curve, color="tab:purple", lw=1, label="actual")
    n = len(curve)
    if predicted_m is not None:
        pred = np.asarray(predicted_m, dtype=np.float64)[:n] * 100.0
        right.plot(gt.times[:len(pred)], pred, color="tab:orange", lw=1,
                   label="predicted by the method")
        title += f"; predicted mean {np.nanmean(pred):.1f} cm"
    if unreliable is not None:
        flags = np.asarray(unreliable, dtype=bool)[:n]
        starts, stops, vals = runs(flags)
        for k, (a, b) in enumerate(zip(starts[vals], stops[vals])):
            right.axvspan(a / gt.fps, b / gt.fps, color="tab:red", alpha=0.12, lw=0,
                          label="flagged unreliable" if k == 0 else None)
    if predicted_m is not None or unreliable is not None:
        right.legend(loc="upper right", fontsize=7)
    right.set_xlabel("time (s)")
    right.set_ylabel("RMSE (cm)")
    right.set_title(title, fontsize=9)
    return _save(fig, path, overwrite)


def plot_path(path: BodyPath | dict, out: str | Path, truth: BodyPath | None = None,
              overwrite: bool = False) -> Path:
    """The body's path seen from above (:class:`imuloco.paths.base.BodyPath`, or a report's
    ``path``: :meth:`BodyPath.from_report`): the pelvis's
    track, the footfalls (right feet as filled triangles, left as open ones, faded by their
    confidence) and, when given, the truth's path and footfalls in grey. Equal axes, metres,
    x the walker's initial heading, y to the left."""
    from matplotlib.colors import to_rgba  # the [viz] extra, as _figure

    if isinstance(path, dict):
        path = BodyPath.from_report(path)
    fig = _figure(7, 6)
    ax = fig.subplots()
    for p, color, label in ((truth, "0.6", "truth"), (path, "tab:blue", path.source)):
        if p is None:
            continue
        ax.plot(p.root_xy[:, 0], p.root_xy[:, 1], color=color, lw=1.5,
                label=f"{label}: pelvis, {p.distance_m():.2f} m")
        for foot, marker in (("right", "v"), ("left", "^")):
            falls = [f for f in p.footfalls if f.foot == foot]
            if not falls:
                continue
            xy = np.stack([f.xy for f in falls])
            rgba = np.tile(to_rgba(color), (len(falls), 1))
            rgba[:, 3] = np.clip([f.confidence for f in falls], 0.2, 1.0)
            ax.scatter(xy[:, 0], xy[:, 1], marker=marker, s=40, edgecolors=rgba,
                       facecolors=rgba if foot == "right" else "none",
                       label=f"{label}: {foot} footfalls")
    if len(path.root_xy):
        ax.plot(*path.root_xy[0], "ko", ms=4)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m, initial heading)")
    ax.set_ylabel("y (m, left)")
    strides = [s.length_m for s in path.strides]
    ax.set_title(f"{path.source}: {len(path.footfalls)} footfalls"
                 + (f", {len(strides)} strides, mean {np.mean(strides):.2f} m" if strides
                    else ""), fontsize=9)
    ax.legend(loc="best", fontsize=7)
    return _save(fig, out, overwrite)
