"""One row per stride: the table a gait study loads beside the per-walker summary.

A stride of one foot runs from one of its strikes to its next (the strikes and foot contacts of
:func:`imuloco.phases.gait_phases`, the events :func:`imuloco.measures.gait.gait_parameters`
summarises). Each row (:data:`STRIDE_FIELDS`):

- ``foot``: ``left`` or ``right``; ``start_s``, ``end_s``: the two strikes, seconds from the
  motion's first frame; ``duration_s``: their difference.
- ``length_m``: horizontal distance the foot's ankle travelled between them (the strides whose
  median is ``stride_length_m``); ``speed_mps``: length over duration.
- ``stance_s``: time that foot was in contact within the stride; ``swing_s``: the rest.
- ``confidence``: the reconstruction's mean predicted error over the stride when the method
  gives one (``None`` otherwise): the predicted rms joint position error, metres, lower is
  better (:class:`imuloco.methods.base.Reconstruction`'s ``error_m``; :func:`with_confidence`).
"""

from __future__ import annotations

from itertools import pairwise
from typing import Any

import numpy as np

from imuloco.core.motion import Motion
from imuloco.phases import gait_phases
from imuloco.phases.gait import GaitPhases

STRIDE_FIELDS = ("foot", "start_s", "end_s", "duration_s", "length_m", "speed_mps", "stance_s",
                 "swing_s", "confidence")


def stride_rows(motion: Motion, phases: GaitPhases | None = None,
                confidence: np.ndarray | None = None, digits: int = 4) -> list[dict[str, Any]]:
    """The strides of ``motion``, both feet, in time order (see the module docstring).

    Parameters
    ----------
    motion : a walking or running Motion whose skeleton maps the ankles.
    phases : its :func:`imuloco.phases.gait_phases` when already computed.
    confidence : ndarray, shape (T,), optional per-frame predicted error of the
        reconstruction, metres (see the module docstring).
    digits : decimals of the rounded floats.
    """
    ph = gait_phases(motion) if phases is None else phases
    fps = motion.fps
    ankles = motion.part_positions(["left_ankle", "right_ankle"])[:, :, [0, 2]]  # (T, 2, 2)
    rows = []
    for k, foot in enumerate(("left", "right")):
        strikes = np.asarray(ph.steps[foot])
        contact = ph.contacts[f"{foot}_foot"]
        for a, b in pairwise(strikes):
            duration = (b - a) / fps
            length = float(np.linalg.norm(ankles[b, k] - ankles[a, k]))
            stance = float(np.count_nonzero(contact[a:b])) / fps
            conf = None if confidence is None else _mean(confidence, a, b, digits)
            rows.append({"foot": foot, "start_s": round(a / fps, digits),
                         "end_s": round(b / fps, digits), "duration_s": round(duration, digits),
                         "length_m": round(length, digits),
                         "speed_mps": round(length / duration, digits),
                         "stance_s": round(stance, digits),
                         "swing_s": round(duration - stance, digits), "confidence": conf})
    rows.sort(key=lambda r: (r["start_s"], r["foot"]))
    return rows


def _mean(values: np.ndarray, a: int, b: int, digits: int) -> float | None:
    """Mean of the finite ``values[a:b]`` (at least frame ``a``), rounded; None when none."""
    v = values[a:max(b, a + 1)]
    v = v[np.isfinite(v)]
    return round(float(v.mean()), digits) if len(v) else None


def with_confidence(rows: list[dict[str, Any]], error_m: np.ndarray | None, fps: float,
                    digits: int = 4) -> list[dict[str, Any]]:
    """Stride rows (of any estimator: times in seconds from the reconstruction's first frame)
    with ``confidence`` the mean of ``error_m`` (T,), metres, over each stride's frames;
    ``error_m`` None leaves the rows as they are."""
    if error_m is None:
        return rows
    last = len(error_m) - 1
    out = []
    for r in rows:
        a = min(last, max(0, round(r["start_s"] * fps)))
        b = min(last + 1, max(0, round(r["end_s"] * fps)))
        out.append({**r, "confidence": _mean(error_m, a, b, digits)})
    return out
