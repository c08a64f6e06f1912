"""The real-data protocol (``imuloco bench --real DIR``): gait from real sensors against a
reference measured otherwise.

For every trial of every data set found under ``DIR`` (:mod:`imuloco.io.realimu`) and every
sensor it has, the gait is measured once over the whole recording, as a user would, by the
estimator for that placement (:mod:`imuloco.measures.sensorgait`; ``reconstruction``: the
former path, a right-ankle reconstruction's gait, with ``--baseline``) and compared within the
reference's windows, by the reference's own definitions of a bout's stride, speed and cadence
and of its steps' window, which each reader declares (:class:`~imuloco.io.realimu.
GaitDefinition`), the estimate read the same way:

- ``steps_err_pct``: steps found against the reference's (a foot sensor: twice its foot's
  contacts against twice the reference's contacts of that foot).
- ``cadence_err_pct``: cadence from the contacts' span (steps/min), per bout (strides over the
  whole trial: the contacts over its time, pauses included).
- ``ic_median_ms`` / ``ic_mean_ms``: absolute timing error of initial contacts matched one to
  one to the reference's (nearest within :data:`IC_TOLERANCE_S`), with the missed and extra.
- ``stride_err_m`` / ``stride_err_pct``: mean stride length per bout against the reference's.
- ``speed_err_pct``: walking speed per bout.
- a foot sensor against a bout's distance over all its steps (ipol-gait's 10 m: 2 x 10 m /
  steps, over the bout's time from the first foot-off): the foot's distance over the swings
  that end at its contacts in the bout (:func:`bout_contacts`), over its steps and over the
  same time. ``stride_mean_err_pct`` / ``speed_mean_err_pct``: the estimate as a walk's
  summary reports it (the mean of the complete strides, speed from the contacts' span),
  against the same reference.
- the body's path (issue 40; estimator ``path:<source>``, :mod:`imuloco.paths`, for every
  placement with a path estimator): ``distance_err_pct``, the path's distance within each
  bout of a fixed length (ipol-gait's 10 m) against it; ``stride_err_pct`` / ``stride_err_m``,
  its strides' mean per bout against the reference's; ``path_final_pct`` with Vicon's stride
  ends (the worn foot's footfalls as its path).
- ``bouts_ref`` / ``bouts_measured``: the reference's bouts, and those in which the estimate
  has a stride (the errors above average over these only: an estimator that misses a hard
  bout is not scored on it, so its figures read together with this share).
- ``stance_err_pp``: a foot sensor's mean stance (share of the stride in contact, %) per
  bout against the reference's strides (ipol-gait: from its hand-checked foot-off and
  foot-strike events), in percentage points.
- a reference with the foot's positions at its stride ends (pyshoe-vicon's Vicon): the foot's
  path against them after aligning the start (the first stride's end position and
  direction): error at each stride end (``path_mean_m``) and the final error as % of the
  distance walked (``path_final_pct``); PyShoe's published path is aligned and measured the
  same way (``pyshoe_published`` rows).

Nothing here is fitted to these data: every threshold is the estimator's published default, a
physical bound or the tolerance below.
"""

from __future__ import annotations

import csv
import io
import json
import logging
import math
from collections.abc import Sequence
from itertools import pairwise
from pathlib import Path
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from imuloco.app.pipeline import choose_method, reconstruct_recording, shipped_model
from imuloco.core.recording import Recording
from imuloco.io.atomic import atomic_write
from imuloco.io.realimu import GaitDefinition, GaitReference, RealTrial, find_datasets, read_trials
from imuloco.measures.gait import to_height, to_json
from imuloco.measures.sensorgait import SensorGait, not_measured, sensor_gait
from imuloco.measures.strides import stride_rows
from imuloco.paths.base import BodyPath
from imuloco.paths.metrics import walked_distance
from imuloco.paths.registry import ESTIMATORS, estimate_path
from imuloco.phases import gait_phases

log = logging.getLogger(__name__)

# Matching tolerance of initial contacts, half of the shortest healthy step time (~0.5 s at
# 120 steps/min): a contact is matched to at most one reference contact no further away.
IC_TOLERANCE_S = 0.25
# Literature anchors quoted beside the measurements (not measured here).
ANCHORS = {
    "greene2012_ic_ms": "33.9 ± 10.4 ms heel-strike timing error, shank gyroscope "
                        "(Greene et al. 2012)",
    "rampp2015_stride_cm": "6.26 cm mean absolute stride length error, foot IMU "
                           "(Rampp et al. 2015)",
}
TARGETS = {  # issue 17's targets, by sensor kind
    "foot": {"steps_err_pct": 2, "cadence_err_pct": 2, "ic_median_ms": 40,
             "stride_err_pct": 5, "speed_err_pct": 5},
    "lower_back": {"cadence_err_pct": 3, "stride_err_pct": 10, "speed_err_pct": 10},
}


def match_events(ref: np.ndarray, est: np.ndarray, tol: float = IC_TOLERANCE_S
                 ) -> tuple[np.ndarray, int, int]:
    """One-to-one matching of event times by increasing distance.

    ref, est : ndarray (K,), (M,) seconds.

    Returns
    -------
    (errors, missed, extra): ndarray of ``est - ref`` (s) of the matched pairs, the reference
    events left unmatched and the estimated events left unmatched.
    """
    ref, est = np.sort(np.asarray(ref, float)), np.sort(np.asarray(est, float))
    pairs = matched_pairs(ref, est, tol)
    errs = np.asarray([est[j] - ref[i] for i, j in pairs], float)
    return errs, len(ref) - len(pairs), len(est) - len(pairs)


def matched_pairs(ref: np.ndarray, est: np.ndarray, tol: float = IC_TOLERANCE_S
                  ) -> list[tuple[int, int]]:
    """The ``(ref index, est index)`` pairs of :func:`match_events`' one-to-one matching."""
    ref, est = np.asarray(ref, float), np.asarray(est, float)
    if not len(ref) or not len(est):
        return []
    d = np.abs(ref[:, None] - est[None, :])
    pairs = np.argwhere(d <= tol)
    order = np.argsort(d[pairs[:, 0], pairs[:, 1]], kind="stable")
    used_r, used_e, out = set(), set(), []
    for i, j in pairs[order].tolist():
        if i not in used_r and j not in used_e:
            used_r.add(i)
            used_e.add(j)
            out.append((i, j))
    return out


def bout_contacts(est: np.ndarray, ref: np.ndarray, start: float, end: float) -> np.ndarray:
    """Mask of the estimated contacts ``est`` that are steps of the reference's bout
    ``[start, end]`` s: those matched (:func:`matched_pairs`) to a reference contact of
    ``ref`` inside it, and the unmatched ones inside it. A strike belongs to the same bout on
    both sides whichever side of an edge its estimate falls (ipol-gait's trials end on the
    last strike, which its estimate may follow by a few samples)."""
    inside = lambda t: (t >= start - 1e-9) & (t <= end + 1e-9)
    mask = inside(est)
    for i, j in matched_pairs(ref, est):
        mask[j] = inside(ref[i])
    return mask


def _pct(est: float, ref: float) -> float:
    return 100.0 * (est - ref) / ref if ref and np.isfinite(ref) else math.nan


def _span_cadence(ic: np.ndarray, per_contact: int) -> float:
    ic = np.sort(ic)
    return (60.0 * per_contact * (len(ic) - 1) / (ic[-1] - ic[0])
            if len(ic) >= 2 and ic[-1] > ic[0] else math.nan)


def _mean(values: Sequence[float]) -> float:
    v = np.asarray([x for x in values if x is not None and np.isfinite(x)], float)
    return float(v.mean()) if v.size else math.nan


def _align_path(est: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """``est`` (K, 2) moved so that its first point and first step's direction match ``ref``."""
    a = np.arctan2(*(ref[1] - ref[0])[::-1]) - np.arctan2(*(est[1] - est[0])[::-1])
    rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    return (est - est[0]) @ rot.T + ref[0]


def path_errors(est_times: np.ndarray, est_xy: np.ndarray, ref_times: np.ndarray,
                ref_xy: np.ndarray) -> dict[str, float]:
    """Path error at the reference's stride ends after aligning the start.

    est_times, est_xy : ndarray (T,), (T, 2), the estimated floor path.
    ref_times, ref_xy : ndarray (K,), (K, 2), the reference positions at the stride ends.
    """
    pts = np.stack([np.interp(ref_times, est_times, est_xy[:, i]) for i in range(2)], axis=1)
    pts = _align_path(pts, ref_xy)
    err = np.linalg.norm(pts - ref_xy, axis=1)
    walked = float(np.linalg.norm(np.diff(ref_xy, axis=0), axis=1).sum())
    return {"path_mean_m": float(err[1:].mean()), "path_final_m": float(err[-1]),
            "path_final_pct": 100.0 * float(err[-1]) / walked if walked > 0 else math.nan,
            "distance_m": walked}


def _bout_rows(gait: SensorGait, ref: GaitReference, ref_ic: np.ndarray, per_contact: int,
               side: str | None = None) -> list[dict[str, float]]:
    """Cadence, stride length and speed against each reference bout, by the reference's
    definition, and a foot's stance when the reference has that foot's foot-off events
    (``side``)."""
    out = []
    for b in ref.bouts:
        w = gait.window(b.start - IC_TOLERANCE_S, b.end + IC_TOLERANCE_S).summary()
        inside = ref_ic[(ref_ic >= b.start - 1e-9) & (ref_ic <= b.end + 1e-9)]
        ref_cad = (_span_cadence(inside, per_contact)
                   if ref.definition is GaitDefinition.DISTANCE_OVER_STEPS else b.cadence_spm)
        if ref.definition is GaitDefinition.DISTANCE_OVER_STEPS and gait.swings_m is not None:
            # the reference spreads the bout's 10 m over all its steps, the first from
            # standing and the last into the U-turn or the stop included, and over its time
            # from the first foot-off: so does the estimate, with its own distance (the
            # feet's swings ending at its contacts in the bout) and its own steps. Each foot
            # walks the distance: one foot's contacts (2 steps each) carry it once, both
            # feet's (1 step each) twice, so a stride is the swings' sum over the contacts.
            w["stride_mean_m"], w["speed_mean_mps"] = w["stride_length_m"], w["speed_mps"]
            sel = bout_contacts(gait.initial_contacts, ref_ic, b.start, b.end)
            swung, contacts = float(gait.swings_m[sel].sum()), int(sel.sum())
            walked = swung * per_contact / 2.0
            w["stride_length_m"] = swung / contacts if contacts else math.nan
            w["speed_mps"] = walked / (b.end - b.start) if contacts else math.nan
        if ref.definition is GaitDefinition.STRIDES_OVER_TRIAL:  # foot flat to foot flat:
            # the reference counts strides over the whole trial, pauses included: so does
            # the estimate (its contacts in the same window), not over its contacts' span
            inner = gait.initial_contacts[(gait.initial_contacts > b.start) &
                                          (gait.initial_contacts <= b.end)]
            w["cadence_spm"] = 60.0 * per_contact * len(inner) / (b.end - b.start)
            w["speed_mps"] = w["stride_length_m"] * w["cadence_spm"] / 120.0
        row = {"cadence_ref": ref_cad, "cadence_est": w["cadence_spm"],
               "stride_ref_m": b.stride_length_m, "stride_est_m": w["stride_length_m"],
               "speed_ref_mps": b.speed_mps, "speed_est_mps": w["speed_mps"]}
        if "stride_mean_m" in w:  # the estimate as a walk's summary reports it
            row.update(stride_mean_est_m=w["stride_mean_m"],
                       speed_mean_est_mps=w["speed_mean_mps"])
        if side in ref.final_contacts:
            row.update(stance_est=w["stance_pct"], stance_ref=reference_stance(
                ref.initial_contacts[side], ref.final_contacts[side], b.start, b.end))
        out.append(row)
    return out


def reference_stance(ic: np.ndarray, fc: np.ndarray, start: float, end: float) -> float:
    """Mean stance (%) of the reference's strides within ``[start, end]`` s: from one initial
    contact ``ic`` to the next, the share before the foot-off ``fc`` between them."""
    shares = []
    for a, b in pairwise(ic):
        off = fc[(fc > a) & (fc < b)]
        if start <= a and b <= end and len(off) == 1:
            shares.append((off[0] - a) / (b - a))
    return 100.0 * float(np.mean(shares)) if shares else math.nan


def evaluate_gait(gait: SensorGait, trial: RealTrial, estimator: str) -> dict[str, Any]:
    """One result row: the gait of one sensor of ``trial`` against its reference."""
    ref = trial.reference
    side = gait.placement.split("_")[0] if gait.placement.endswith("_foot") else None
    row: dict[str, Any] = {"dataset": trial.dataset, "recording": trial.name,
                           "sensor": gait.placement, "estimator": estimator,
                           "measured": gait.measured, "reason": gait.reason or ""}
    if not gait.measured:
        return row
    per_contact = gait.steps_per_contact
    if ref.definition is GaitDefinition.STRIDES_OVER_TRIAL:
        se, ref_ic = ref.stride_ends, np.zeros(0)
        # the contact that starts a stride precedes its foot-flat end: count the contacts
        # between the first and the last foot flat
        est_ic = gait.initial_contacts[(gait.initial_contacts > se[0]) &
                                       (gait.initial_contacts <= se[-1])]
        row["steps_ref"] = 2.0 * (len(se) - 1)
        row["steps_est"] = float(per_contact * len(est_ic))
    else:
        # a one-foot estimator against that foot's contacts, others against all contacts
        ref_ic = (ref.initial_contacts[side] if side and per_contact == 2 else
                  np.sort(np.concatenate(list(ref.initial_contacts.values()))))
        # the bouts' span: for ipol-gait the whole trial, U-turn included (it ends on a foot
        # strike; strikes annotated after it, up to 13 s later and some past the recording's
        # end, are outside the trial)
        start = min(b.start for b in ref.bouts)
        end = max(b.end for b in ref.bouts)
        sel = (gait.initial_contacts >= start - IC_TOLERANCE_S) & (
            gait.initial_contacts <= end + IC_TOLERANCE_S)
        in_ref = ref_ic[(ref_ic >= start) & (ref_ic <= end)]
        if ref.definition is GaitDefinition.BOUT_MEANS:  # contacts inside the bouts only
            sel &= np.any([(gait.initial_contacts >= b.start - IC_TOLERANCE_S) &
                           (gait.initial_contacts <= b.end + IC_TOLERANCE_S)
                           for b in ref.bouts], axis=0)
        errs, missed, extra = match_events(in_ref, gait.initial_contacts[sel])
        row.update(steps_ref=float(per_contact * len(in_ref)),
                   steps_est=float(per_contact * int(sel.sum())),
                   ic_matched=len(errs), ic_missed=missed, ic_extra=extra,
                   ic_median_ms=1e3 * float(np.median(np.abs(errs))) if len(errs) else math.nan,
                   ic_mean_ms=1e3 * float(np.mean(np.abs(errs))) if len(errs) else math.nan,
                   ic_bias_ms=1e3 * float(np.mean(errs)) if len(errs) else math.nan)
    row["steps_err_pct"] = _pct(row["steps_est"], row["steps_ref"])
    bouts = _bout_rows(gait, ref, ref_ic, per_contact, side if per_contact == 2 else None)
    for key in ("cadence", "stride", "speed"):
        unit = {"cadence": "", "stride": "_m", "speed": "_mps"}[key]
        r = _mean([b[f"{key}_ref{unit}"] for b in bouts])
        e = _mean([b[f"{key}_est{unit}"] for b in bouts])
        row[f"{key}_ref"], row[f"{key}_est"] = r, e
        row[f"{key}_err_pct"] = _mean([_pct(b[f"{key}_est{unit}"], b[f"{key}_ref{unit}"])
                                      for b in bouts])
    if bouts and "stride_mean_est_m" in bouts[0]:
        for key, unit in (("stride", "_m"), ("speed", "_mps")):
            row[f"{key}_mean_est"] = _mean([b[f"{key}_mean_est{unit}"] for b in bouts])
            row[f"{key}_mean_err_pct"] = _mean([_pct(b[f"{key}_mean_est{unit}"],
                                                     b[f"{key}_ref{unit}"]) for b in bouts])
    row["stride_err_m"] = _mean([b["stride_est_m"] - b["stride_ref_m"] for b in bouts])
    row["bouts_ref"] = len(bouts)
    row["bouts_measured"] = sum(bool(np.isfinite(b["stride_est_m"])) for b in bouts)
    if bouts and "stance_est" in bouts[0]:  # a foot against its foot-off events
        row["stance_est"] = _mean([b["stance_est"] for b in bouts])
        row["stance_ref"] = _mean([b["stance_ref"] for b in bouts])
        row["stance_err_pp"] = _mean([b["stance_est"] - b["stance_ref"] for b in bouts])
    if ref.stride_ends is not None and gait.path is not None:  # a path known at stride ends
        if ref.stride_points is not None and len(ref.stride_points) >= 2:
            xy = gait.path[:, :2] * ([1.0, -1.0] if ref.path_z_down else [1.0, 1.0])
            row.update(path_errors(gait.times, xy, ref.stride_ends, ref.stride_points))
        # per-stride length errors against Vicon's stride lengths (matched by stride end)
        row["stride_mae_m"] = _stride_mae(gait, ref.stride_ends, ref.stride_points)
    return row


def evaluate_path(trial: RealTrial, placement: str) -> dict[str, Any]:
    """One result row for the body's path from the sensor at ``placement`` (estimator
    ``path:<source>``, :mod:`imuloco.paths`) against the reference: per bout, the path's
    distance within the bout's window against a fixed distance (ipol-gait's 10 m,
    ``distance_err_pct``) and its strides' mean length against the reference's
    (``stride_err_pct``, ``stride_err_m``); with Vicon's stride ends, the footfalls' path
    against them (``path_final_pct``, ``path_mean_m``, as :func:`path_errors`)."""
    ref = trial.reference
    height = ref.height_m if np.isfinite(ref.height_m) else None
    path = estimate_path(trial.recording.select([placement]), placement, height)
    row: dict[str, Any] = {"dataset": trial.dataset, "recording": trial.name,
                           "sensor": placement, "estimator": f"path:{path.source}",
                           "measured": bool(path.strides), "reason": "" if path.strides
                           else path.note}
    if not path.strides:
        return row
    dist, stride, stride_m = [], [], []
    for b in ref.bouts:
        if np.isfinite(b.distance_m):
            d = walked_distance(_window(path, b.start, b.end))
            dist.append(_pct(d, b.distance_m))
        inside = [s.length_m for s in path.strides if s.start_s >= b.start - IC_TOLERANCE_S
                  and s.end_s <= b.end + IC_TOLERANCE_S]
        if inside and np.isfinite(b.stride_length_m):
            stride.append(_pct(float(np.mean(inside)), b.stride_length_m))
            stride_m.append(float(np.mean(inside)) - b.stride_length_m)
    row.update(distance_err_pct=_mean(dist), stride_err_pct=_mean(stride),
               stride_err_m=_mean(stride_m), bouts_ref=len(ref.bouts),
               bouts_measured=len(stride))
    if ref.stride_ends is not None and ref.stride_points is not None and len(
            ref.stride_points) >= 2:
        own = [f for f in path.footfalls if f.foot == placement.split("_")[0]]
        if len(own) >= 2:
            xy = np.stack([f.xy for f in own]) * ([1.0, -1.0] if ref.path_z_down else 1.0)
            row.update(path_errors(np.array([f.time_s for f in own]), xy, ref.stride_ends,
                                   ref.stride_points))
    return row


def _window(path: BodyPath, start: float, end: float) -> BodyPath:
    """``path`` between ``start`` and ``end`` seconds (its pelvis only)."""
    keep = (path.times_s >= start) & (path.times_s <= end)
    return BodyPath(path.times_s[keep], path.root_xy[keep], None, [], [], path.source, "")


def _stride_mae(gait: SensorGait, ends: np.ndarray, points: np.ndarray) -> float:
    """Mean absolute error of the foot's stride lengths between the reference's stride ends
    (the estimated path's rest positions there against Vicon's)."""
    xy = np.stack([np.interp(ends, gait.times, gait.path[:, i]) for i in range(2)], axis=1)
    est = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    ref = np.linalg.norm(np.diff(points, axis=0), axis=1)
    return float(np.mean(np.abs(est - ref)))


def published_path_row(trial: RealTrial) -> dict[str, Any] | None:
    """PyShoe's published ZUPT path of a pyshoe-vicon trial, measured as ours is."""
    ref = trial.reference
    if ref.published_path is None or ref.stride_points is None:
        return None
    if len(trial.recording.placements) != 1:
        raise ValueError(f"{trial.dataset} {trial.name}: a published path needs a recording of "
                         f"one sensor, got {trial.recording.placements}")
    row = {"dataset": trial.dataset, "recording": trial.name,
           "sensor": trial.recording.placements[0],
           "estimator": "pyshoe_published", "measured": True, "reason": ""}
    row.update(path_errors(ref.path_times, ref.published_path, ref.stride_ends,
                           ref.stride_points))
    return row


def reconstruction_gait(trial: RealTrial, placement: str, fitted) -> SensorGait:
    """Gait read from a reconstruction's strikes (:func:`imuloco.measures.gait.
    gait_parameters`): the sensor's signal reconstructed by ``fitted`` (a model of that
    placement, or the former path: a right-ankle model reading it as a shin phone), on the
    walker's height when the reference gives it."""
    rec = trial.recording.select([placement])
    rec = Recording(rec.times, rec.acc, rec.gyro, list(fitted.placements_))
    motion, _ = reconstruct_recording(rec, fitted)
    if np.isfinite(trial.reference.height_m):
        motion = to_height(motion, trial.reference.height_m)
    ph = gait_phases(motion)
    frames = np.concatenate([ph.steps["left"], ph.steps["right"]]).astype(int)
    order = np.argsort(frames, kind="stable")
    # each strike's swing: its ankle's floor distance from its previous strike (the first:
    # from the recording's start), as a foot sensor's swings_m
    swings = []
    for side in ("left", "right"):
        floor = motion.part_positions([f"{side}_ankle"])[:, 0][:, [0, 2]]
        at = np.asarray(ph.steps[side], int)
        swings.append(np.linalg.norm(np.diff(floor[np.r_[0, at]], axis=0), axis=1))
    ankle = motion.part_positions(["right_ankle"])[:, 0]
    rows = [r for r in stride_rows(motion, ph) if r["foot"] == "right"]
    t = np.arange(motion.num_frames) / motion.fps + rec.times[0]
    return SensorGait(placement, f"reconstruction ({fitted.name}, "
                      f"{fitted.placements_[0]} model) strikes", strides=rows,
                      initial_contacts=frames[order] / motion.fps + rec.times[0],
                      steps_per_contact=1, times=t,
                      path=ankle[:, [0, 2, 1]] * [1.0, -1.0, 1.0],  # z up: (x, -z, y)
                      swings_m=np.concatenate(swings)[order])


def run_real(folder: str | Path, out: str | Path | None = None, limit: int | None = None,
             baseline: bool = False, progress: bool = False) -> list[dict[str, Any]]:
    """Run the protocol on every data set under ``folder``; write ``real.json``,
    ``real.csv`` and ``README.md`` into ``out`` when given.

    limit : at most this many trials per data set.
    baseline : also measure the gait of the reconstruction (estimator ``reconstruction``):
        by the shipped ``learned`` model of the sensor's placement, else (the former path)
        the right-ankle one reading the sensor as a shin phone.
    """
    rows: list[dict[str, Any]] = []
    models: dict[str, Any] = {}

    def model_for(placement: str):
        if placement not in models:
            own = shipped_model("learned", placement) is not None
            models[placement] = choose_method(
                "learned" if own else None, placement=placement if own else "right_ankle")[0]
        return models[placement]

    for layout, path in find_datasets(folder):
        trials = list(read_trials(path, layout, limit))
        for trial in tqdm(trials, desc=layout, unit="trial", disable=not progress):
            for placement in trial.recording.placements:
                try:
                    gait = sensor_gait(trial.recording, placement,
                                       height_m=trial.reference.height_m,
                                       sensor_height_m=trial.reference.sensor_height_m)
                except ValueError as e:  # e.g. a lower back without the walker's height
                    # said aloud: a library's failure must not pass for a recording without
                    # gait (mobgap once raised here at some sampling rates)
                    log.warning("%s %s, %s: not measured: %s", trial.dataset, trial.name,
                                placement, e)
                    gait = not_measured(placement, "", str(e))
                rows.append(evaluate_gait(gait, trial, "imuloco"))
                if baseline:
                    try:
                        base = reconstruction_gait(trial, placement, model_for(placement))
                        rows.append(evaluate_gait(base, trial, "reconstruction"))
                    except ValueError as e:  # a motion the phase detector cannot read
                        log.warning("%s %s, %s: reconstruction not measured: %s",
                                    trial.dataset, trial.name, placement, e)
                        rows.append({"dataset": trial.dataset, "recording": trial.name,
                                     "sensor": placement, "estimator": "reconstruction",
                                     "measured": False, "reason": str(e)})
                if placement in ESTIMATORS:  # the body's path (issue 40)
                    rows.append(evaluate_path(trial, placement))
            if row := published_path_row(trial):
                rows.append(row)
    if out is not None:
        write_results(rows, out)
    return rows


SUMMARY_KEYS = ("steps_err_pct", "cadence_err_pct", "ic_median_ms", "stride_err_m",
                "stride_err_pct", "speed_err_pct", "stance_err_pp", "stride_mae_m",
                "path_final_pct", "stride_mean_err_pct", "speed_mean_err_pct",
                "distance_err_pct")


def summarize(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per data set, sensor and estimator: the mean absolute value of each error (the median
    of the recordings' IC medians), the share of reference contacts matched by an estimate
    (``ic_matched_pct``), the share of the reference's bouts with an estimated stride
    (``bouts_measured_pct``), the recordings measured, and the shares within target."""
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        groups.setdefault((r["dataset"], r["sensor"], r["estimator"]), []).append(r)
    out = []
    for (ds, sensor, est), rs in groups.items():
        ok = [r for r in rs if r.get("measured")]
        s: dict[str, Any] = {"dataset": ds, "sensor": sensor, "estimator": est,
                             "recordings": len(rs), "measured": len(ok)}
        for k in SUMMARY_KEYS:
            vals = np.asarray([abs(r[k]) for r in ok if k in r and r[k] is not None and
                               np.isfinite(r[k])], float)
            if vals.size:
                s[k] = float(np.median(vals) if k == "ic_median_ms" else vals.mean())
        # the share of reference contacts with an estimate within IC_TOLERANCE_S: what the
        # median timing error leaves out (a walker whose contacts all come a third of a
        # stride early has no median at all)
        matched = sum(r.get("ic_matched", 0) for r in ok)
        missed = sum(r.get("ic_missed", 0) for r in ok)
        if matched + missed:
            s["ic_matched_pct"] = 100.0 * matched / (matched + missed)
        bouts = sum(r.get("bouts_ref", 0) for r in ok)
        if bouts:
            s["bouts_measured_pct"] = 100.0 * sum(r.get("bouts_measured", 0) for r in ok) / bouts
        kind = "foot" if sensor.endswith("_foot") else sensor
        for k, lim in TARGETS.get(kind, {}).items():
            vals = [abs(r[k]) for r in ok if k in r and np.isfinite(r[k])]
            if vals:
                s[f"{k}_within_target"] = float(np.mean(np.asarray(vals) <= lim))
        out.append(s)
    return out


COLUMNS = [("dataset", "data set"), ("sensor", "sensor"), ("estimator", "estimator"),
           ("measured", "n"), ("steps_err_pct", "steps %"), ("cadence_err_pct", "cadence %"),
           ("ic_median_ms", "IC ms"), ("ic_matched_pct", "IC matched %"),
           ("bouts_measured_pct", "bouts %"), ("stride_err_m", "stride m"),
           ("stride_err_pct", "stride %"), ("speed_err_pct", "speed %"),
           ("stance_err_pp", "stance pp"),
           ("stride_mae_m", "stride MAE m"), ("path_final_pct", "path end %"),
           ("distance_err_pct", "distance %")]


def table(summary: list[dict[str, Any]]) -> str:
    """Markdown table of :func:`summarize`'s rows (mean absolute errors)."""
    head = "| " + " | ".join(c[1] for c in COLUMNS) + " |"
    sep = "|" + "|".join("---" if i < 3 else "---:" for i in range(len(COLUMNS))) + "|"
    lines = [head, sep]
    for s in summary:
        cells = []
        for key, _ in COLUMNS:
            v = s.get(key)
            cells.append("–" if v is None else (f"{v:.3f}" if key in ("stride_err_m",
                                                                      "stride_mae_m")
                                                else f"{v:.1f}" if isinstance(v, float)
                                                else str(v)))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


LATER_COLUMNS = ("stride_mean_est", "stride_mean_err_pct", "speed_mean_est",
                 "speed_mean_err_pct")


# the definition under which :func:`evaluate_gait` also reports the strides' mean
# (``stride_mean_err_pct``), in words
MEAN_DEFINITION = GaitDefinition.DISTANCE_OVER_STEPS
MEAN_DEFINITION_WORDS = ("the bout's distance over all its steps and over the bout's time from "
                         "the first foot-off")


def _and(words: Sequence[str]) -> str:
    """``a``, ``a and b``, ``a, b and c``."""
    return ", ".join(words[:-1]) + " and " + words[-1] if len(words) > 1 else words[0]


def _mean_note(summary: list[dict[str, Any]]) -> str:
    """The README's sentence on the rows whose stride and speed follow the reference's
    definition (:data:`MEAN_DEFINITION`): what the walk's summary (the strides' mean) gives
    there."""
    rows = [s for s in summary if "stride_mean_err_pct" in s]
    if not rows:
        return ""
    sensors: dict[str, list[str]] = {}
    for s in rows:
        sensors.setdefault(s["dataset"], [])
        if s["sensor"] not in sensors[s["dataset"]]:
            sensors[s["dataset"]].append(s["sensor"])
    named = "; ".join(f"{ds}'s {_and(ss)}" for ds, ss in sensors.items())
    figs = "; ".join(f"{s['dataset']} {s['sensor']} ({s['estimator']}) stride "
                     f"{s['stride_mean_err_pct']:.1f} %, speed {s['speed_mean_err_pct']:.1f} %"
                     for s in rows)
    return (f"{named}: stride and speed by the reference's definition "
            f"({MEAN_DEFINITION.value}), {MEAN_DEFINITION_WORDS}, the foot's distance over its "
            "swings in the bout in its place. The mean of the complete strides and speed from "
            "the contacts' span, as a walk's summary reports them, against the same reference "
            f"(`stride_mean_err_pct`, `speed_mean_err_pct`): {figs}.\n\n")


def write_results(rows: list[dict[str, Any]], out: str | Path) -> None:
    """``real.json`` (rows, summary, anchors), ``real.csv`` (rows) and ``README.md``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    summary = summarize(rows)
    clean = lambda r: {k: (v if isinstance(v, (str, bool)) else to_json({"v": v})["v"])
                       for k, v in r.items()}
    payload = {"summary": [clean(s) for s in summary], "rows": [clean(r) for r in rows],
               "anchors": ANCHORS, "targets": TARGETS, "ic_tolerance_s": IC_TOLERANCE_S}
    with atomic_write(out / "real.json", "w") as fh:
        fh.write(json.dumps(payload, indent=1) + "\n")
    keys = list(dict.fromkeys(k for r in rows for k in r))
    # columns added since the first release go last: the others keep their place
    keys = [k for k in keys if k not in LATER_COLUMNS] + [k for k in LATER_COLUMNS
                                                          if k in keys]
    buf = io.StringIO()
    writer = csv.DictWriter(buf, keys)
    writer.writeheader()
    writer.writerows(clean(r) for r in rows)
    with atomic_write(out / "real.csv", "w") as fh:
        fh.write(buf.getvalue())
    with atomic_write(out / "README.md", "w") as fh:
        fh.write("# Gait from real sensors against real references\n\n"
                 "`imuloco bench --real DIR` (mean absolute errors over the recordings; IC: "
                 "median of the recordings' median absolute timing errors; IC matched: the "
                 f"share of the reference's contacts with an estimate within "
                 f"{1e3 * IC_TOLERANCE_S:.0f} ms; bouts: the share of the reference's walking "
                 "bouts in which the estimate has a stride, the bouts that stride, cadence and "
                 "speed errors average over; stance pp: a foot's stance against the "
                 "reference's foot-off and foot-strike events, in percentage points).\n\n"
                 + table(summary) + "\n\n" + _mean_note(summary) + "Anchors from the literature: "
                 + "; ".join(ANCHORS.values()) + ".\n")
