"""Long recordings in bounded memory: reconstruct in pieces and write the BVH piece by piece.

A reconstruction holds every joint's rotation per frame, and its analysis every joint's
position: 0.45 MB per second of recording in one piece (16 GB for ten hours). Here the
imported recording (a few MB per hour) is calibrated whole, as in one piece, then reconstructed
``piece_s`` seconds at a time. Each piece is preceded and followed by ``warmup_s`` seconds of
signal that the method runs over and whose frames are dropped, so that a method's windows,
filters and look-ahead see the same input as in one piece, and is turned about the vertical
and moved so that it continues the previous piece at the join (the methods integrate the
heading and the root's path from their own start). For methods with a finite window (the baselines) the result equals the
one-piece reconstruction to rounding; recurrent methods (``learned``) forget their start
within the warm-up, so pieces differ from one piece by what their state still remembers.
Gait parameters are computed per piece and combined (:func:`combine`), but a foot or
lower-back sensor's, measured on its own signal, over the whole recording; a method's per-frame
confidence (:meth:`imuloco.methods.base.Method.reconstruct_signals_full`) is cut with its piece
and summarised over the whole recording (a few bytes per frame).
"""

from __future__ import annotations

import itertools
import logging
import time
from collections.abc import Iterator, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from imuloco.app.confidence import Confidence
from imuloco.app.export import figure_height, rest_of
from imuloco.app.pipeline import (
    ModelChoice,
    calibrated,
    choose_model,
    feet_pinned_by,
    ignored_sensors,
    require_extras,
)
from imuloco.app.report import MotionInfo, Pieces, ReconstructionReport, build_report
from imuloco.core.motion import Motion
from imuloco.core.recording import Recording
from imuloco.core.rigs import DEFAULT_RIG, MODEL, apply_rig
from imuloco.io.atomic import check_output
from imuloco.io.bvh import write_bvh_pieces
from imuloco.measures.gait import (
    Gait,
    Plausibility,
    gait_parameters,
    height_scale,
    plausibility,
    to_height,
)
from imuloco.measures.sensorgait import GaitReport, estimator_of, gait_report
from imuloco.measures.strides import stride_rows
from imuloco.methods.base import Reconstruction
from imuloco.methods.fallback import FallbackReport, fallback_signals
from imuloco.methods.postprocess import pin_detected_contacts
from imuloco.methods.training import frame_times, model_frames
from imuloco.ops.rotations import about_y, qmul, qrot
from imuloco.paths.follow import PieceFollower, estimated_path
from imuloco.phases import gait_phases
from imuloco.sensors.multi import read_sensors
from imuloco.sensors.reallog import LogReport, read_log

_log = logging.getLogger(__name__)

PIECE_SECONDS = 600.0  # 10 min: 18,000 frames at 30 fps, ~100 MB of analysis
WARMUP_SECONDS = 20.0  # longer than any method's window (learned: 120 frames = 4 s)
# Recordings longer than LONG_SECONDS are reconstructed in pieces of AUTO_PIECE_SECONDS by
# default (plan_pieces). Measured (docs/results/speed/reconstruct.md, shipped shin model, one
# thread): one piece peaks at the stack's ~450 MB plus ~0.6 MB a second of recording (60 s:
# 495 MB, 600 s: 843 MB), pieces at what their window (piece and both warm-ups) costs in one
# piece whatever the length (1 h in pieces of 300 s: 885 MB; 600 s in pieces of 120 s: 616
# MB, no more CPU than one piece). Past 300 s one piece would cost more than pieces of 120 s.
LONG_SECONDS = 300.0
AUTO_PIECE_SECONDS = 120.0


def _yaw(q: np.ndarray) -> np.ndarray:
    """Heading angle (radians about +Y) of rotations q (..., 4): where they turn +Z."""
    f = qrot(q, np.broadcast_to([0.0, 0.0, 1.0], q.shape[:-1] + (3,)))
    return np.arctan2(f[..., 0], f[..., 2])


def continue_from(piece: Motion, at: int, root_rotation: np.ndarray, root: np.ndarray
                  ) -> Motion:
    """``piece`` turned about the vertical and moved horizontally so that its frame ``at`` has
    the root heading of ``root_rotation`` (4,) and the horizontal root position of ``root``
    (3,), metres."""
    turn = about_y(_yaw(root_rotation) - _yaw(piece.rotations[at, 0]))
    rotations = piece.rotations.copy()
    rotations[:, 0] = qmul(np.broadcast_to(turn, rotations[:, 0].shape), rotations[:, 0])
    path = qrot(np.broadcast_to(turn, piece.root.shape[:-1] + (4,)), piece.root)
    shift = root - path[at]
    shift[1] = 0.0
    return Motion(piece.skeleton, rotations, path + shift, piece.fps, piece.name)


def shifted(rows: list[dict[str, Any]], offset_s: float) -> list[dict[str, Any]]:
    """Stride rows (:func:`imuloco.measures.strides.stride_rows`) of a piece starting
    ``offset_s`` into the recording, on the recording's clock; a stride across a join is in
    neither piece's rows."""
    return [{**r, "start_s": round(r["start_s"] + offset_s, 4),
             "end_s": round(r["end_s"] + offset_s, 4)} for r in rows]


def reconstruct_pieces(rec: Recording, method, pin: bool = False,
                       piece_s: float = PIECE_SECONDS, warmup_s: float = WARMUP_SECONDS
                       ) -> Iterator[Motion]:
    """The reconstruction of ``rec`` (calibrated, at any rate) at the method's frame rate, as
    consecutive Motions of ``piece_s`` seconds (see the module docstring); a tail shorter than
    a second joins the last piece.

    ``pin``: pin each piece's feet during their detected contacts
    (:func:`imuloco.methods.postprocess.pin_detected_contacts`), as the pipeline does for
    methods that do not pin them themselves."""
    for piece in reconstruction_pieces(rec, method, pin, piece_s, warmup_s):
        yield piece.motion


def reconstruction_pieces(rec: Recording, method, pin: bool = False,
                          piece_s: float = PIECE_SECONDS, warmup_s: float = WARMUP_SECONDS
                          ) -> Iterator[Reconstruction]:
    """:func:`reconstruct_pieces` with each piece's confidence: consecutive
    :class:`imuloco.methods.base.Reconstruction` pieces (``error_m``, ``unreliable`` cut as
    the motion)."""
    for full, _ in fallback_pieces(rec, method, pin, piece_s, warmup_s, fallback=False):
        yield full


def fallback_pieces(rec: Recording, method, pin: bool = False, piece_s: float = PIECE_SECONDS,
                    warmup_s: float = WARMUP_SECONDS, fallback: bool = True
                    ) -> Iterator[tuple[Reconstruction, FallbackReport | None]]:
    """:func:`reconstruction_pieces` with, when ``fallback``, the per-part fallback applied to
    each piece before its feet are pinned, as in one piece
    (:func:`imuloco.methods.fallback.fallback_signals`, run over the piece and its warm-ups so
    that its windows see the signal one piece sees), and each piece's
    :class:`~imuloco.methods.fallback.FallbackReport` (None without ``fallback``)."""
    fps = method.fps_
    rec = rec.select(method.placements_)
    # the grid Method.reconstruct reads: (F, 6 S), ~50 MB for 10 h
    signals = model_frames(rec, fps, method.gaps_missing)
    frames = len(signals)
    # a piece longer than the recording is the whole of it (1e308 s overflowed round())
    step = max(1, round(min(piece_s * fps, frames)))
    warm = max(1, round(min(warmup_s * fps, frames)))
    last, start = None, 0
    while start < frames:
        stop = min(frames, start + step)
        if frames - stop < fps:  # a tail under 1 s joins this piece (one frame has no gait)
            stop = frames
        # the warm-up before and as much signal after: the last frames see their look-ahead
        begin, end = max(0, start - warm), min(frames, stop + warm)
        full, report = method.reconstruct_signals_full(signals[begin:end]), None
        if fallback:  # before the pinning, as reconstruct_recording does
            full, report = fallback_signals(full, signals[begin:end], method)
        motion = full.motion
        if pin:
            motion = pin_detected_contacts(motion)
        if last is not None:
            motion = continue_from(motion, start - begin - 1, *last)
        piece = motion.slice(start - begin, stop - begin)
        last = (piece.rotations[-1, 0].copy(), piece.root[-1].copy())
        err, flags = (None if a is None else np.asarray(a)[start - begin:stop - begin]
                      for a in (full.error_m, full.unreliable))
        cut = None if report is None else report.sliced(start - begin, stop - begin)
        yield Reconstruction(piece, err, flags, full.note), cut
        start = stop


def plan_pieces(recording_path, piece_s: float | None = None, whole: str | None = None,
                sensors: Sequence[tuple[str, str | Path]] = (), **options: Any
                ) -> tuple[float | None, tuple[Recording, LogReport] | None]:
    """Whether ``imuloco reconstruct`` works in pieces, and how long they are.

    piece_s : the user's choice (``--piece-seconds``): seconds, 0 for one piece, None to
        decide here: pieces of :data:`AUTO_PIECE_SECONDS` for a recording longer than
        :data:`LONG_SECONDS` (memory then stays flat in the recording's length), else one.
    whole : why the outputs need the whole motion at once (``"--video"``...), or None: a long
        recording is then reconstructed in one piece, with a warning.
    sensors, options : :func:`imuloco.sensors.multi.read_sensors`'s, to read the log when
        deciding (several sensors are read in one piece: pieces read one log).

    Returns the piece length (None: one piece) and the log read to decide (None when it was
    not read), for :func:`reconstruct_to_bvh` or :func:`imuloco.app.pipeline.reconstruct_file`.
    """
    if piece_s is not None:
        return (float(piece_s) if piece_s > 0 else None), None
    if "placement" in options:
        require_extras(options["placement"])  # before reading a long log
    log = read_sensors(recording_path, sensors, **options)
    seconds = float(log[0].times[-1] - log[0].times[0]) if len(log[0].times) else 0.0
    if seconds <= LONG_SECONDS:
        return None, log
    why = whole or ("--sensor" if sensors else None)
    if why is not None:
        _log.warning("%.0f s of recording reconstructed in one piece (%s needs the whole "
                     "motion): memory grows with its length; drop %s to work in pieces",
                     seconds, why, why)
        return None, log
    return AUTO_PIECE_SECONDS, log


def combine(reports: list[dict[str, float]], frames: list[int]) -> dict[str, float]:
    """Per-piece values combined: counts (``steps``, ``duration_s``) summed, the rest averaged
    with each piece weighted by its frames (NaN pieces left out)."""
    out: dict[str, float] = {}
    w = np.asarray(frames, dtype=np.float64)
    for key in reports[0]:
        v = np.array([r[key] for r in reports], dtype=np.float64)
        if key in ("steps", "duration_s"):
            out[key] = float(np.nansum(v))
        else:
            ok = np.isfinite(v)
            out[key] = float(np.average(v[ok], weights=w[ok])) if ok.any() else float("nan")
    return out


def reconstruct_to_bvh(recording_path, output: str | Path, method=None, model=None,
                       placement: str = "right_ankle", fmt: str = "auto",
                       calibrate: bool = True, pin: bool | None = None,
                       platform: str | None = None, overwrite: bool = False,
                       piece_s: float = PIECE_SECONDS, warmup_s: float = WARMUP_SECONDS,
                       progress: bool = False, unit: str = "cm",
                       height: float | None = None, rig: str | None = DEFAULT_RIG,
                       columns: dict[str, str] | None = None, fallback: bool = True,
                       imported: tuple[Recording, LogReport] | None = None) -> ReconstructionReport:
    """Import a log, reconstruct it in pieces and write the BVH to ``output`` piece by piece.

    Parameters as :func:`imuloco.app.pipeline.reconstruct_file` (``method`` a name, or a fitted
    method); returns the report (:func:`imuloco.app.report.build_report`), with gait
    parameters and plausibility checks combined over the pieces (:func:`combine`; for a foot
    or lower-back sensor, its own gait with ``gait_source``, ``gait_note`` and ``strides`` as
    in one piece, the pieces' combined as ``motion_gait``), ``pieces`` (their count and
    seconds) and ``confidence`` (:meth:`imuloco.app.confidence.Confidence.to_json` over the
    whole recording, scaled with ``height``). and, for a placement with a path estimator, ``path``
    (each piece follows it: :class:`imuloco.paths.follow.PieceFollower`). ``unit``: the BVH's
    length unit
    (:func:`imuloco.io.bvh.write_bvh`).
    ``height``: the wearer's body height in metres; every piece is scaled to it
    (:func:`imuloco.measures.gait.to_height`, the same factor for all) before its gait is
    measured and it is written.
    ``rig``: the rig preset written (:func:`imuloco.core.rigs.apply_rig`; None: the model's
    skeleton as it is), its T-pose rest :func:`imuloco.app.export.rest_of` the first piece,
    used for every piece.
    ``fallback``: the per-part fallback on every piece (:func:`fallback_pieces`), reported
    over the whole recording as in one piece.
    ``imported``: the log at ``recording_path`` already read (:func:`plan_pieces`), not read again.
    """
    t0 = time.perf_counter()
    check_output(Path(output), overwrite)  # before any work (the first piece is made first)
    require_extras(placement)  # before reading a long log
    rec, log_report = imported or read_log(recording_path, placement=placement, fmt=fmt,
                                      platform=platform, columns=columns)
    available = [placement, *(p for p in rec.placements if p != placement)]
    if method is None or isinstance(method, str):
        choice = choose_model(method, model, placement, progress=progress, available=available)
    else:
        choice = ModelChoice(method, "given", f"given fitted method {method.name!r}")
    fitted = choice.method
    ignored = ignored_sensors(rec.placements, fitted)  # named, as in one piece
    for source in log_report.sensors:
        source.used = source.placement not in ignored
    calibration = None
    raw = rec  # a foot or lower-back sensor's gait reads its own signal, as in one piece
    if calibrate:
        rec, calibration = calibrated(rec.select(fitted.placements_))
    if pin is None:
        pin = not fitted.pins_feet
    frames = len(frame_times(rec, fitted.fps_))
    path = estimated_path(rec, fitted.placements_[0], height)
    follower = PieceFollower(path) if path is not None else None
    gait, checks, sizes, confidences, fallbacks = [], [], [], [], []
    strides: list[dict[str, Any]] = []  # every piece's strides, on the recording's clock
    final: list = []  # the last piece and its gait phases
    bar = tqdm(total=frames, desc="reconstruct", unit="frame", disable=not progress)

    def pieces() -> Iterator[Motion]:
        for full, report in fallback_pieces(rec, fitted, pin, piece_s, warmup_s, fallback):
            piece = full.motion
            fallbacks.append(report)
            conf = Confidence.of(full, piece.fps, f"method {fitted.name!r}")
            if height is not None:  # a uniform scale: the joins stay joined
                k = height_scale(piece.skeleton, height)
                piece, conf = to_height(piece, height), conf.scaled(k)  # error_m is a length
            if follower is not None:
                piece = follower(piece)
            confidences.append(conf)
            phases = gait_phases(piece)  # the piece's contacts: found once, read twice
            gait.append(gait_parameters(piece, phases))
            strides.extend(shifted(stride_rows(piece, phases), sum(sizes) / piece.fps))
            checks.append(plausibility(piece, phases.contacts))
            sizes.append(piece.num_frames)
            bar.update(piece.num_frames)
            final[:] = [piece, phases]
            yield piece

    def on_rig(motions: Iterator[Motion]) -> Iterator[Motion]:
        rest = None
        for piece in motions:
            if rig is not None and rig != MODEL:
                rest = rest_of(piece) if rest is None else rest
                piece = apply_rig(piece, rig, rest)
            yield piece

    written = on_rig(pieces())
    first = next(written, None)  # its skeleton sets the head's End Site (figure_height)
    write_bvh_pieces(itertools.chain([] if first is None else [first], written), frames,
                     output, unit=unit, overwrite=overwrite,
                     height=None if first is None else figure_height(first.skeleton))
    bar.close()
    motion_gait = Gait(**combine(gait, sizes))
    if estimator_of(placement) is None:
        walk = GaitReport(motion_gait, "the reconstructed motion, per piece", None, strides)
    else:  # the sensor's own gait over the whole recording; ``final``, on the reported
        # skeleton, gives the stature when ``height`` is None
        sensor = gait_report(*final[:1], raw, placement, height, final[1])
        walk = GaitReport(replace(sensor.gait, duration_s=motion_gait.duration_s),
                          sensor.source, sensor.note, sensor.strides, motion_gait)
    return build_report(
        recording=log_report, raw=raw, model=choice, placement=placement,
        calibration=calibration, feet_pinned_by=feet_pinned_by(pin, fitted),
        motion=MotionInfo(frames, fitted.fps_, round((frames - 1) / fitted.fps_, 3)),
        height_m=height, gait=walk, plausibility=Plausibility(**combine(checks, sizes)),
        confidence=Confidence.concatenate(confidences), started=t0,
        pieces=Pieces(len(sizes), piece_s, warmup_s),
        path=None if follower is None else follower.report(),
        fallback=FallbackReport.concatenate(fallbacks) if fallback else
        FallbackReport(False, note="switched off (--no-fallback)"))

