"""The report of one reconstruction: typed, built in one place (:func:`build_report`).

``imuloco reconstruct --report`` (in one piece or with ``--piece-seconds``), ``batch``'s
``NAME.json`` and the demo's ``report.json`` are :meth:`ReconstructionReport.to_json`; its keys
are a contract that scripts rely on. The pieces are the measures' typed results
(:class:`imuloco.measures.gait.Gait`, :class:`imuloco.measures.gait.Plausibility`,
:class:`imuloco.measures.sensorgait.GaitReport`), the import's
(:class:`imuloco.sensors.reallog.LogReport`), the model's (:class:`ModelChoice
<imuloco.app.pipeline.ModelChoice>`) and the method's confidence
(:class:`imuloco.app.confidence.Confidence`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

from imuloco.app.confidence import Confidence
from imuloco.core.motion import Motion
from imuloco.core.recording import Recording
from imuloco.measures.gait import Gait, Plausibility, signal_rhythm, to_json
from imuloco.measures.sensorgait import GaitReport, model_gait_note
from imuloco.measures.strides import with_confidence
from imuloco.sensors.placement import get_placement
from imuloco.sensors.reallog import LogReport

if TYPE_CHECKING:
    from imuloco.app.pipeline import ModelChoice


@dataclass(frozen=True)
class MotionInfo:
    """The reconstruction's size: ``frames``, ``fps`` and ``duration_s`` (rounded to ms)."""

    frames: int
    fps: float
    duration_s: float

    @classmethod
    def of(cls, motion: Motion) -> MotionInfo:
        return cls(motion.num_frames, motion.fps, round(motion.duration, 3))

    def to_json(self) -> dict[str, Any]:
        return {"frames": self.frames, "fps": self.fps, "duration_s": self.duration_s}


@dataclass(frozen=True)
class Pieces:
    """How a long recording was cut (:mod:`imuloco.app.chunked`): ``count`` pieces of
    ``seconds``, each run with ``warmup_seconds`` of signal on either side."""

    count: int
    seconds: float
    warmup_seconds: float

    def to_json(self) -> dict[str, Any]:
        return {"count": self.count, "seconds": self.seconds,
                "warmup_seconds": self.warmup_seconds}


@dataclass
class ReconstructionReport:
    """What a reconstruction found, as typed fields; :meth:`to_json` gives the JSON report.

    recording : the import (:class:`imuloco.sensors.reallog.LogReport`); its ``sensors``
        (file, clock offset and rule, whether the model read it) are the JSON's ``sensors``.
    calibration : per placement, the rotation found (``None``: not calibrated).
    feet_pinned_by : ``"method"``, ``"pipeline"`` or ``"none"``.
    model : where the model came from (:class:`imuloco.app.pipeline.ModelChoice`).
    placement : the placement read.
    motion : frames, fps and duration of the reconstruction.
    pieces : how a long recording was cut (``None``: in one piece).
    height_m : the wearer's height given (``None``: the model skeleton's proportions).
    gait, gait_source, gait_note, strides, motion_gait :
        :func:`imuloco.measures.sensorgait.gait_report` (``motion_gait``: a foot or lower-back
        sensor's reconstructed motion's own gait, None otherwise; ``strides`` None: not
        listed, for a motion reconstructed in pieces).
    signal_cadence_spm : the cadence of the raw signal (Welch), steps per minute.
    signal_swing_deg : for a sensor on the shank, the degrees the raw signal turns through in
        a stride (:func:`imuloco.measures.gait.signal_swing`), against which ``plausibility``'s
        ``{side}_shank_swing_deg`` reads the reconstruction's legs; None for other sensors.
    plausibility : :func:`imuloco.measures.gait.plausibility`.
    skeleton : the user's rig the motion was retargeted onto (``None``: the model's).
    confidence : the method's per-frame predicted error and unreliable flags
        (:class:`imuloco.app.confidence.Confidence`, in metres of the reported motion: scaled
        with ``height_m``, on the model's skeleton also when retargeted onto ``skeleton``);
        the JSON's ``confidence`` is its summary.
    seconds : wall time of the whole reconstruction.
    path : the body's path that drove the root (:func:`imuloco.paths.follow.path_report`:
        source, distance, strides, and the followed animation's own); None for a placement
        without a path estimator.
    warnings : what the import and reconstruction warned of (``batch``; None elsewhere).
    batch : what ``imuloco batch`` ran it with (recording, model hash, placement, height,
        unit), which marks its outputs complete; ``None`` outside a batch.
    """

    recording: LogReport
    calibration: list[dict[str, Any]] | None
    feet_pinned_by: str
    model: ModelChoice
    placement: str
    motion: MotionInfo
    height_m: float | None
    gait: Gait
    gait_source: str
    gait_note: str | None
    strides: list[dict[str, Any]] | None
    signal_cadence_spm: float | None
    signal_swing_deg: float | None
    plausibility: Plausibility
    motion_gait: Gait | None = None
    pieces: Pieces | None = None
    skeleton: dict[str, Any] | None = None
    confidence: Confidence | None = None
    seconds: float = 0.0
    batch: dict[str, Any] | None = None
    warnings: list[str] | None = None
    path: dict[str, Any] | None = None

    @property
    def method(self) -> str:
        """The registry name of the method that reconstructed."""
        return self.model.method.name

    def to_json(self) -> dict[str, Any]:
        """The JSON report (keys in this order; ``calibration`` only when calibrated, the
        other optional keys only when set)."""
        out: dict[str, Any] = {"recording": self.recording.to_json()}
        if self.calibration is not None:
            out["calibration"] = self.calibration
        out.update(feet_pinned_by=self.feet_pinned_by, method=self.method,
                   model=self.model.description, placement=self.placement,
                   sensors=[s.to_json() for s in self.recording.sensors],
                   motion=self.motion.to_json())
        if self.pieces is not None:
            out["pieces"] = self.pieces.to_json()
        out.update(height_m=self.height_m, gait=self.gait.to_json(),
                   gait_source=self.gait_source, gait_note=self.gait_note)
        if self.strides is not None:
            out["strides"] = self.strides
        out.update(signal_cadence_spm=self.signal_cadence_spm,
                   signal_swing_deg=self.signal_swing_deg,
                   plausibility=self.plausibility.to_json())
        if self.motion_gait is not None:
            out["motion_gait"] = self.motion_gait.to_json()
        if self.path is not None:
            out["path"] = self.path
        if self.skeleton is not None:
            out["skeleton"] = self.skeleton
        if self.confidence is not None:
            out["confidence"] = self.confidence.to_json()
        if self.warnings is not None:
            out["warnings"] = self.warnings
        out["seconds"] = self.seconds
        if self.batch is not None:
            out["batch"] = self.batch
        return out

    def __getitem__(self, key: str) -> Any:
        """``report[key]``: the JSON report's value (code written against the dict)."""
        return self.to_json()[key]


def build_report(*, recording: LogReport, raw: Recording, model: ModelChoice, placement: str,
                 calibration: list[dict[str, Any]] | None, feet_pinned_by: str,
                 motion: MotionInfo, height_m: float | None, gait: GaitReport,
                 plausibility: Plausibility, confidence: Confidence, started: float,
                 pieces: Pieces | None = None, skeleton: dict[str, Any] | None = None,
                 path: dict[str, Any] | None = None) -> ReconstructionReport:
    """The report of a reconstruction, in one piece (:func:`imuloco.app.pipeline.
    reconstruct_file`) or in pieces (:func:`imuloco.app.chunked.reconstruct_to_bvh`).

    ``raw`` is the imported recording before calibration: the cadence and a shank sensor's
    swing of its raw signal (:func:`imuloco.measures.gait.signal_rhythm`) are read from the
    model's sensor here. Each stride gets the confidence of its frames
    (:func:`imuloco.measures.strides.with_confidence`). ``started``: the
    :func:`time.perf_counter` of the start, for ``seconds``.
    """
    k = raw.placements.index(model.method.placements_[0])
    cadence, swing = signal_rhythm(raw, k)  # the raw signal's, beside the motion's
    on_shank = get_placement(raw.placements[k]).on_shank
    strides = (None if gait.strides is None else
               with_confidence(gait.strides, confidence.error_m, motion.fps))
    if gait.motion_gait is None and gait.note is None:  # the motion's gait: say so, and check
        checks = plausibility.to_json()  # it against the sensor's own rhythm and swing
        gait = replace(gait, note=model_gait_note(
            placement, gait.gait.to_json(), cadence, swing if on_shank else None,
            {side: checks.get(f"{side}_shank_swing_deg") for side in ("left", "right")}))
    return ReconstructionReport(
        recording=recording, calibration=calibration, feet_pinned_by=feet_pinned_by,
        model=model, placement=placement, motion=motion, height_m=height_m, gait=gait.gait,
        gait_source=gait.source, gait_note=gait.note, strides=strides,
        signal_cadence_spm=to_json({"v": cadence})["v"],
        signal_swing_deg=(to_json({"v": swing})["v"]
                          if on_shank else None),
        plausibility=plausibility, motion_gait=gait.motion_gait, pieces=pieces,
        skeleton=skeleton, confidence=confidence, path=path,
        seconds=round(time.perf_counter() - started, 2))
