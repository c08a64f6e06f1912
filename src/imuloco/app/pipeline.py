"""The user's path from a phone recording to an animation, as library functions.

:func:`reconstruct_file` does what ``imuloco reconstruct`` does: import the log
(:mod:`imuloco.sensors.reallog`: sort, de-duplicate, detect units, align, resample and filter),
calibrate how the phone sits on the leg (:mod:`imuloco.sensors.calibration`), reconstruct with a
method (:mod:`imuloco.methods`), pin the feet during their contacts
(:func:`imuloco.methods.postprocess.pin_feet`) and report gait parameters and plausibility
checks (:mod:`imuloco.measures.gait`). :func:`demo` runs the same path on a phone recording
simulated from a bundled clip and writes every output next to the ground truth.

Which model reconstructs (:func:`choose_method`): a model file when given; otherwise the
pretrained model shipped in ``imuloco/data/models/<method>_<model>.npz`` (``model`` the
placement's, :data:`imuloco.sensors.placement.PRESETS`; the ``learned``
method by default); when none is shipped or its method cannot be imported (torch missing), the
best available baseline (``ridge``, then ``knn``, then ``mean``) fitted on the bundled sample
on the fly, which the report says.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from importlib.util import find_spec
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from scipy.stats import spearmanr
from tqdm.auto import tqdm

from imuloco.app.confidence import Confidence
from imuloco.app.export import write_reconstruction
from imuloco.app.render import render_outputs
from imuloco.app.report import MotionInfo, ReconstructionReport, build_report
from imuloco.app.summary import confidence_markdown, demo_markdown  # noqa: F401 (re-exported)
from imuloco.core.motion import Motion
from imuloco.core.recording import Recording
from imuloco.core.retarget import Rig, retarget
from imuloco.core.rigs import DEFAULT_RIG, check_rig_name
from imuloco.data import MODELS_DIR
from imuloco.errors import InputError, ModelFileError, UnknownNameError
from imuloco.io.atomic import atomic_write, check_outputs
from imuloco.io.bvh import check_joint_names
from imuloco.io.database import load_sample
from imuloco.io.motionfile import read_motion
from imuloco.io.sensorlog import write_generic_csv
from imuloco.measures.gait import Gait, Plausibility, height_scale, to_height, to_json
from imuloco.measures.metrics import evaluate, rmse_per_frame
from imuloco.measures.sensorgait import gait_report
from imuloco.methods import get_method, load_model, method_class
from imuloco.methods.fallback import FallbackReport, fallback_recording
from imuloco.methods.postprocess import pin_detected_contacts, pin_feet
from imuloco.ops.rotations import angle
from imuloco.paths.follow import follow_recording
from imuloco.phases import foot_contacts, gait_phases
from imuloco.sensors.calibration import calibrate
from imuloco.sensors.multi import read_sensors
from imuloco.sensors.placement import PRESETS
from imuloco.sensors.reallog import recording_name
from imuloco.sensors.simulate import simulate
from imuloco.viz.plots import plot_errors, plot_phases, plot_signals

if TYPE_CHECKING:
    from imuloco.methods.base import Method

log = logging.getLogger(__name__)

DEFAULT_METHOD = "learned"
# The baseline to fall back on. ridge rather than knn: knn is closer on simulated signals
# (MPJPE 5.0 against 6.1 cm, heldout-styles on the sample) but ridge generalizes to a real
# phone: on the RealWorld shin recording its rhythm cadence is 102 steps/min (raw signal 101),
# knn's jittery output gives 160-200.
FALLBACK = "ridge"
DEMO_CLIP = "dataset-2_walk_normal_001"
DEMO_SEED = 7


# Placements whose pipeline needs the [gait] extra, and the module of it each names (their
# declarations' ``needs``, imuloco.sensors.placement.PRESETS).
GAIT_EXTRA = {name: p.needs[0] for name, p in PRESETS.items() if p.needs}


def require_extras(placement: str) -> None:
    """Raise :class:`~imuloco.errors.MissingExtraError` (``pip install 'imuloco[gait]'``)
    before any work when ``placement``'s pipeline needs a package that is not installed
    (:meth:`imuloco.sensors.placement.Placement.require_extra`)."""
    if placement in PRESETS:
        PRESETS[placement].require_extra()


def shipped_placements(method: str = DEFAULT_METHOD) -> list[str]:
    """The placements ``method`` has a pretrained model of in the package."""
    return sorted(p.stem.removeprefix(f"{method}_") for p in MODELS_DIR.glob(f"{method}_*.npz"))


def shipped_model(method: str, placement: str) -> Path | None:
    """Path of the pretrained model of ``method`` for ``placement`` shipped with the package
    (``<method>_<model>.npz``, ``model`` the placement's declaration's)."""
    model = PRESETS[placement].model if placement in PRESETS else None
    path = None if model is None else MODELS_DIR / f"{method}_{model}.npz"
    return path if path is not None and path.is_file() else None


def shipped_combination(method: str, placements: Sequence[str], primary: str) -> Path | None:
    """The shipped model of ``method`` that reads several of the recording's ``placements``,
    ``primary`` among them: ``<method>_<a>+<b>[+...].npz`` (its placements in its name), the
    one reading the most; None when none matches."""
    found = []
    for path in MODELS_DIR.glob(f"{method}_*+*.npz"):
        names = path.stem.removeprefix(f"{method}_").split("+")
        if primary in names and set(names) <= set(placements):
            found.append((len(names), path.name, path))
    return max(found)[2] if found else None


def ignored_sensors(placements: Sequence[str], method) -> list[str]:
    """The recording's sensors (``placements``) the fitted ``method`` does not read; a warning
    names them (a second sensor is never dropped silently)."""
    ignored = [p for p in placements if p not in method.placements_]
    if ignored:
        log.warning("the model reads %s only: the recording's %s sensor(s) %s are ignored (no "
                    "shipped model reads %s; train one with imuloco train --placement %s)",
                    "+".join(method.placements_), len(ignored), ", ".join(ignored),
                    "+".join([*method.placements_, *ignored]),
                    ",".join([*method.placements_, *ignored]))
    return ignored


@dataclass(frozen=True)
class ModelChoice:
    """The fitted method that will reconstruct and where it came from.

    source : ``"file"`` (a model file the user gave), ``"shipped"`` (a pretrained model of the
        package), ``"fitted"`` (fitted on the bundled sample on the fly) or ``"given"`` (an
        already fitted method passed in).
    description : the sentence reports print (``model`` in the JSON).
    path : the model file, for ``"file"`` and ``"shipped"``.
    """

    method: Method
    source: Literal["file", "shipped", "fitted", "given"]
    description: str
    path: Path | None = None

    def __str__(self) -> str:
        return self.description


def choose_model(method: str | None = None, model: str | Path | None = None,
                 placement: str = "right_ankle", exclude: Sequence[str] = (),
                 progress: bool = False, db=None,
                 available: Sequence[str] | None = None) -> ModelChoice:
    """The fitted method that will reconstruct, with its source (see the module docstring).

    Parameters
    ----------
    method : registry name (see ``imuloco methods``); ``None`` for the default.
    model : a model file written by ``imuloco train`` (takes precedence over ``method``).
    placement : the sensor placement the model must know.
    exclude : clip names left out when a method is fitted on the bundled sample (the demo
        leaves its own clip out).
    db : the bundled sample when already loaded.
    available : every sensor the recording has (``placement`` first; ``None``: only it). A
        shipped model reading several of them (:func:`shipped_combination`) is preferred to
        ``placement``'s own; a model file may read any of them.
    """
    require_extras(placement)
    if model is not None:
        fitted = load_model(model)
        have = [placement] if available is None else list(available)
        if placement not in fitted.placements_ or not set(fitted.placements_) <= set(have):
            raise InputError(f"{model}: the model was trained for {fitted.placements_}, not "
                             f"{'+'.join(have)!r} (--placement {fitted.placements_[0]} reads "
                             "it, with --sensor for its other sensors)")
        return ModelChoice(fitted, "file", f"model file {model} (method {fitted.name!r})",
                           Path(model))
    name = DEFAULT_METHOD if method is None else method
    several = None if not available or len(available) < 2 else shipped_combination(
        name, available, placement)
    path = several or shipped_model(name, placement)
    if path is not None:
        try:
            return ModelChoice(load_model(path), "shipped",
                               f"pretrained {name!r} model shipped with imuloco ({path.name})",
                               path)
        except (ModelFileError, ImportError) as e:
            log.warning("cannot load the shipped model %s: %s", path, e)
    if method is not None:
        method_class(method)  # fails clearly for an unknown or uninstalled method
    if method is None:
        method = FALLBACK
        why = (f"no pretrained {DEFAULT_METHOD!r} model is usable here, so the best available "
               f"baseline {method!r} was fitted")
        if path is None and find_spec("torch") is not None:  # no model for this placement
            log.warning("no shipped model for %s (models ship for %s): fitting %r on the "
                        "bundled sample's clips instead, a rough stand-in (on simulated held-out "
                        "styles 6-8 cm MPJPE, feet sliding 94-188 cm/s: "
                        "docs/results/placements/); its gait is not to be trusted",
                        placement, ", ".join(shipped_placements()), method)
    else:
        why = f"method {method!r} has no shipped model for {placement}, so it was fitted"

    db = load_sample(progress=progress) if db is None else db
    keep = [i for i, lab in enumerate(db.labels) if lab["name"] not in set(exclude)]
    fitted = get_method(method).fit(db.subset(keep), placements=[placement], noise="phone",
                                    seed=0, progress=progress)
    return ModelChoice(fitted, "fitted",
                       f"{why} on the bundled sample ({len(keep)} clips) on the fly")


def choose_method(method: str | None = None, model: str | Path | None = None,
                  placement: str = "right_ankle", exclude: Sequence[str] = (),
                  progress: bool = False, db=None) -> tuple[Method, str]:
    """:func:`choose_model` as a pair (fitted method, sentence saying where it came from)."""
    choice = choose_model(method, model, placement, exclude, progress, db)
    return choice.method, choice.description


def calibrated(rec: Recording) -> tuple[Recording, list[dict[str, Any]]]:
    """``rec`` with its leg sensors turned into their segments' anatomical frames
    (:func:`imuloco.sensors.calibration.calibrate`) and, per placement, what was found (the
    report's ``calibration``)."""
    rec, mounts = calibrate(rec)
    return rec, [
        {"placement": p, "up_from": m.up_source, "still_s": round(m.still_s, 2),
         "swings": m.swings, "rotation_deg": round(float(np.degrees(angle(m.rotation))), 2),
         "rotation_xyzw": [round(float(v), 6) for v in m.rotation]}
        for p, m in zip(rec.placements, mounts)]


def reconstruct_recording(rec: Recording, method, calibrate: bool = True,
                          pin: bool | None = None, fallback: bool = True
                          ) -> tuple[Motion, dict[str, Any]]:
    """Reconstruct a Motion from an imported recording with a fitted method.

    Parameters
    ----------
    rec : Recording in m/s^2 and rad/s with the method's placement(s).
    method : a fitted :class:`imuloco.methods.base.Method`.
    calibrate : rotate leg sensors into their segment's anatomical frame first
        (:func:`imuloco.sensors.calibration.calibrate`).
    pin : move the root so that feet in contact (detected on the reconstruction) do not slide;
        ``None``: unless the method pins its feet itself (``method.pins_feet``: it knows its
        contacts better than a detection on its output).
    fallback : move the parts the sensor does not see toward a neutral pose where the model
        does not know the motion, and every part toward the standing pose where the sensor is
        still (:func:`imuloco.methods.fallback.fallback_recording`; ``--no-fallback``).

    Returns
    -------
    The motion at the model's frame rate and a dict with the calibration found
    (``calibration``), ``feet_pinned_by`` and ``confidence`` (the method's per-frame predicted
    error and flags, :class:`imuloco.app.confidence.Confidence`, from
    :meth:`imuloco.methods.base.Method.reconstruct_full`) and ``fallback`` (what the fallback
    did, :class:`imuloco.methods.fallback.FallbackReport`).
    """
    info: dict[str, Any] = {}
    rec = rec.select(method.placements_)
    if calibrate:
        rec, info["calibration"] = calibrated(rec)
    full = method.reconstruct_full(rec)
    if fallback:  # the per-part fallback toward neutral poses (issue 41): its one call site
        full, info["fallback"] = fallback_recording(full, rec, method)
    else:
        info["fallback"] = FallbackReport(False, note="switched off (--no-fallback)")
    motion = full.motion
    info["confidence"] = Confidence.of(full, motion.fps, f"method {method.name!r}")
    if pin is None:
        pin = not method.pins_feet
    info["feet_pinned_by"] = feet_pinned_by(pin, method)
    if pin:
        motion = pin_detected_contacts(motion)
    return motion, info


def animate_recording(rec: Recording, method, calibrate: bool = True, pin: bool | None = None,
                      fallback: bool = True, height: float | None = None
                      ) -> tuple[Motion, dict[str, Any]]:
    """The animation ``imuloco reconstruct`` writes of an imported recording:
    :func:`reconstruct_recording`, scaled to the wearer's ``height`` (metres, None: the
    model's skeleton; :func:`imuloco.measures.gait.to_height`), its root following the path
    of the recording's first placement (:func:`imuloco.paths.follow.follow_recording`).
    ``imuloco bench run`` scores its path figures on this same animation.

    Returns the motion and :func:`reconstruct_recording`'s dict, its ``confidence`` scaled
    with the skeleton, plus ``path`` (the report's path, None for a placement without an
    estimator)."""
    motion, info = reconstruct_recording(rec, method, calibrate, pin, fallback)
    if height is not None:
        k = height_scale(motion.skeleton, height)
        motion, info["confidence"] = to_height(motion, height), info["confidence"].scaled(k)
    motion, info["path"] = follow_recording(motion, rec, method.placements_[0], height)
    return motion, info


def feet_pinned_by(pin: bool, method) -> str:
    """Who keeps the feet from sliding (the report's ``feet_pinned_by``): ``"pipeline"``
    (``pin``), ``"method"`` (it pins them itself) or ``"none"``."""
    return "pipeline" if pin else ("method" if method.pins_feet else "none")


def load_rig(path: str | Path):
    """The user's rig (:class:`imuloco.core.retarget.Rig`) from a motion file (BVH, ASF/AMC):
    its joint names, offsets and the poses of its frames (one T-pose frame will do). A rig
    whose joints do not map every canonical body part is refused, naming the parts."""
    motion = read_motion(path)
    check_joint_names(motion.skeleton.names, str(path))  # the BVH written on it keeps them
    return Rig.measure([motion], where=str(path))


def onto_rig(motion: Motion, rig, contacts: dict[str, np.ndarray] | None = None) -> Motion:
    """``motion`` retargeted onto ``rig`` (:func:`imuloco.core.retarget.retarget`: global
    rotations per body part, root path scaled by leg length, feet on the floor), then its
    root moved so that feet in contact in ``motion`` do not slide on the rig either
    (:func:`imuloco.methods.postprocess.pin_feet`): other proportions add no skating.
    ``contacts``: ``motion``'s :func:`imuloco.phases.foot_contacts` when already found."""
    c = foot_contacts(motion) if contacts is None else contacts
    return pin_feet(retarget(motion, rig), np.stack([c["left_foot"], c["right_foot"]], axis=1))


def reconstruct_file(recording_path: str | Path | Sequence[str | Path], model=None,
                     method: str | None = None, placement: str = "right_ankle",
                     fmt: str = "auto", calibrate: bool = True, pin: bool | None = None,
                     progress: bool = False, fitted: Method | ModelChoice | None = None,
                     platform: str | None = None, skeleton: str | Path | None = None,
                     height: float | None = None, columns: dict[str, str] | None = None,
                     sensors: Sequence[tuple[str, str | Path]] = (), fallback: bool = True
                     ) -> tuple[Motion, ReconstructionReport]:
    """Import a phone's sensor log and reconstruct the wearer's motion.

    Parameters
    ----------
    recording_path : a log file, a Sensor Logger folder or an (accelerometer, gyroscope) pair
        (see :func:`imuloco.sensors.reallog.read_log`; a RealWorld ``acc_*.csv`` finds its
        ``gyroscope_*.csv`` itself).
    model, method, placement : see :func:`choose_model`.
    fmt : log format or ``"auto"``.
    calibrate, pin, fallback : see :func:`reconstruct_recording`.
    progress : show progress bars (tqdm) on stderr.
    fitted : an already fitted method or chosen model (skips :func:`choose_model`).
    platform : Sensor Logger exports: ``"ios"`` or ``"android"`` (default: from the export's
        metadata, else guessed with a warning).
    skeleton : a motion file of the user's rig: the motion comes out on it (:func:`onto_rig`;
        gait is measured before, on the model's skeleton).
    height : the wearer's body height in metres: the skeleton, and so every length and speed,
        is scaled to it (:func:`imuloco.measures.gait.to_height`) before gait is measured.
    columns : a CSV's own names of the generic log's columns (``{"time": "timestamp", ...}``,
        :func:`imuloco.io.sensorlog.parse_columns`).
    sensors : further sensors, ``(placement, file)`` each, put on the log's clock
        (:func:`imuloco.sensors.multi.read_sensors`). With several sensors the shipped model
        reading them is chosen (:func:`choose_model`'s ``available``); a sensor no model reads
        is named in a warning and in the report's ``sensors`` (``used``: false).

    Returns
    -------
    The Motion (on the model's training skeleton or ``skeleton``'s rig, at the model's frame
    rate) and the :class:`ReconstructionReport`: the import, the calibration, the model, gait
    parameters from the best estimator for the placement
    (:func:`imuloco.measures.sensorgait.gait_report`) with per-stride rows, plausibility checks
    and the cadence of the raw signal (``report.to_json()`` for JSON).
    """
    require_extras(placement)  # before reading a long log
    rig = None if skeleton is None else load_rig(skeleton)  # and a bad rig file before its work
    steps = ["import", "model", "reconstruct", "gait"]
    bar = tqdm(total=len(steps), desc="reconstruct", unit="step", disable=not progress)
    t0 = time.perf_counter()
    bar.set_postfix_str("reading the log")
    rec, log_report = read_sensors(recording_path, sensors, placement=placement, fmt=fmt,
                                   platform=platform, columns=columns)
    if placement not in rec.placements:  # a file that names its sensors: its first leads
        placement = rec.placements[0]
        require_extras(placement)
    available = [placement, *(p for p in rec.placements if p != placement)]
    bar.update()
    bar.set_postfix_str("model")
    if fitted is None:
        choice = choose_model(method, model, placement, progress=progress, available=available)
    elif isinstance(fitted, ModelChoice):
        choice = fitted
    else:
        choice = ModelChoice(fitted, "given", f"given fitted method {fitted.name!r}")
    fitted = choice.method
    ignored = ignored_sensors(rec.placements, fitted)
    for source in log_report.sensors:
        source.used = source.placement not in ignored
    bar.update()
    bar.set_postfix_str(f"{fitted.name} on {rec.times[-1]:.0f} s")
    motion, info = animate_recording(rec, fitted, calibrate, pin, fallback, height)
    confidence, path = info["confidence"], info["path"]
    report_name = recording_name(recording_path if isinstance(recording_path, (str, Path))
                                 else recording_path[0])
    motion.name = report_name
    bar.update()
    bar.set_postfix_str("gait")
    phases = gait_phases(motion)  # the reported motion's contacts: found once, read thrice
    gait = gait_report(motion, rec, placement, height, phases)
    checks = Plausibility.of(motion, phases.contacts)
    info_motion, rig_json = MotionInfo.of(motion), None
    if skeleton is not None:
        bar.set_postfix_str(f"retargeting onto {Path(skeleton).name}")
        motion = onto_rig(motion, rig, phases.contacts)
        motion.name = report_name
        rig_json = {"file": str(skeleton), "joints": motion.skeleton.num_joints}
    report = build_report(
        recording=log_report, raw=rec, model=choice, placement=placement,
        calibration=info.get("calibration"), feet_pinned_by=info["feet_pinned_by"],
        motion=info_motion, height_m=height, gait=gait, plausibility=checks,
        confidence=confidence, started=t0, skeleton=rig_json, path=path,
        fallback=info["fallback"])
    bar.update()
    bar.close()
    return motion, report


def demo(out_dir: str | Path, method: str | None = None, model: str | Path | None = None,
         clip: str = DEMO_CLIP, overwrite: bool = False, progress: bool = False,
         unit: str = "cm", skeleton: str | Path | None = None,
         preset: str | None = None) -> dict[str, Any]:
    """The README's first command: a bundled clip, a simulated phone, a reconstruction.

    Takes ``clip`` from the bundled sample, simulates a phone on the right ankle with phone
    noise (irregular timestamps, bias, misplacement; written as ``recording.csv``), runs
    :func:`reconstruct_file` on that file (a model fitted on the fly leaves ``clip`` out) and
    writes into ``out_dir``: ``reconstruction.bvh``, the side-by-side ground truth and
    reconstruction ``demo.mp4`` and ``demo.gif``, the viewer ``demo.html``, plots
    (``signals.png``, ``phases.png``, ``errors.png``) and ``report.md`` / ``report.json`` with
    the metrics (:func:`imuloco.measures.metrics.evaluate`) and gait parameters of both, and
    for a method with a confidence its predicted error beside the actual one
    (:func:`confidence_check`; per frame in ``errors.png`` and the viewer).
    ``unit`` is the BVH's length unit (``cm`` or ``m``).
    With ``skeleton`` (a motion file of the user's rig) ``reconstruction.bvh`` is on that rig
    (:func:`onto_rig`), else on rig ``preset`` (:func:`imuloco.app.export.write_reconstruction`;
    default ``bvh-default``, the model's joint names in a T-pose rest); the video, viewer and
    metrics stay on the model's skeleton.

    Returns
    -------
    The report dict (also in ``report.json``), with ``files`` listing what was written.
    """
    t0 = time.perf_counter()
    out = Path(out_dir)
    names = ["recording.csv", "reconstruction.bvh", "demo.mp4", "demo.gif", "demo.html",
             "signals.png", "phases.png", "errors.png", "report.md", "report.json"]
    paths = {n: out / n for n in names}
    check_outputs(paths.values(), overwrite,
                  inputs=[p for p in (model, skeleton) if p is not None])
    if skeleton is not None and preset is not None:
        raise InputError("a rig preset and a skeleton file are exclusive: give one")
    preset = None if skeleton is not None else check_rig_name(preset or DEFAULT_RIG)
    bar = tqdm(total=5, desc="demo", unit="step", disable=not progress)

    db = load_sample()
    matches = [c for c in db.clips if c.name == clip]
    if not matches:
        raise UnknownNameError(f"no clip {clip!r} in the bundled sample; it has "
                       f"{[c.name for c in db.clips]}")
    gt = matches[0]
    # the model and the rig before any file is written: a bad --model or --skeleton leaves
    # no partial output
    bar.set_postfix_str("model")
    choice = choose_model(method, model, "right_ankle", exclude=[clip], db=db)
    rig = None if skeleton is None else load_rig(skeleton)
    bar.update()
    bar.set_postfix_str("simulating a phone")
    rec = simulate(gt, ["right_ankle"], rate=100.0, noise="phone", seed=DEMO_SEED)
    out.mkdir(parents=True, exist_ok=True)
    write_generic_csv(rec, paths["recording.csv"], overwrite=overwrite)
    bar.update()
    bar.set_postfix_str("reconstructing")
    if choice.source == "shipped":
        choice = replace(choice, description=choice.description + (
            "; it was trained on every clip of the data set, this one included, so these "
            "metrics are optimistic (see `imuloco bench` for held-out numbers)"))
    motion, recon = reconstruct_file(paths["recording.csv"], fitted=choice)
    report = recon.to_json()
    n = min(gt.num_frames, motion.num_frames)
    gt_cut, rec_cut = gt.slice(0, n), motion.slice(0, n)
    rec_cut.name = "reconstruction"
    conf = recon.confidence.sliced(0, n)
    write_reconstruction(rec_cut if rig is None else onto_rig(rec_cut, rig),
                         paths["reconstruction.bvh"], preset, unit=unit, overwrite=overwrite)
    bar.update()

    bar.set_postfix_str("rendering")
    titles = ["ground truth", f"reconstruction ({recon.method})"]
    render_outputs([gt_cut, rec_cut], titles, [paths["demo.mp4"], paths["demo.gif"]],
                   paths["demo.html"], overwrite=overwrite, confidence=[None, conf])
    bar.update()

    bar.set_postfix_str("report")
    phases = gait_phases(rec_cut)
    plot_signals(rec, paths["signals.png"], phases, overwrite=overwrite)
    plot_phases(phases, paths["phases.png"], overwrite=overwrite)
    plot_errors(gt_cut, rec_cut, paths["errors.png"], overwrite=overwrite,
                predicted_m=conf.error_m, unreliable=conf.unreliable)
    report["clip"] = clip
    report["metrics"] = to_json(evaluate(gt_cut, rec_cut))
    report["confidence_check"] = confidence_check(gt_cut, rec_cut, conf)
    truth = gait_phases(gt_cut)  # the ground truth's contacts: found once, read twice
    report["gait_ground_truth"] = Gait.of(gt_cut, truth).to_json()
    report["plausibility_ground_truth"] = Plausibility.of(gt_cut, truth.contacts).to_json()
    report["files"] = names
    report["seconds"] = round(time.perf_counter() - t0, 2)
    with atomic_write(paths["report.json"], "w") as f:
        f.write(json.dumps(report, indent=2) + "\n")
    with atomic_write(paths["report.md"], "w") as f:
        f.write(demo_markdown(report))
    bar.update()
    bar.close()
    return report


def confidence_check(gt: Motion, rec: Motion, confidence: Confidence) -> dict[str, Any]:
    """A method's predicted error against the actual one, frame by frame, where a ground
    truth exists (the demo's ``confidence_check``): ``mean_predicted_error_m``,
    ``mean_actual_error_m`` (the per-frame rms joint position error,
    :func:`imuloco.measures.metrics.rmse_per_frame`, the quantity predicted), their
    ``ratio`` (predicted / actual: 1 is calibrated, below 1 over-confident), their 90th
    percentiles (``p90_predicted_error_m``, ``p90_actual_error_m``), the ``spearman`` rank
    correlation of the two over frames, and the actual error on ``unreliable`` and
    ``reliable`` frames (metres); every value ``None`` for a method without confidence."""
    keys = ("mean_predicted_error_m", "mean_actual_error_m", "ratio", "p90_predicted_error_m",
            "p90_actual_error_m", "spearman", "actual_error_unreliable_m",
            "actual_error_reliable_m")
    out: dict[str, float | None] = dict.fromkeys(keys)
    if not confidence.available:
        return out
    actual = rmse_per_frame(gt, rec) / 100.0
    pred = confidence.error_m[:len(actual)]
    ok = np.isfinite(pred)
    if ok.sum() < 2:
        return out
    out["mean_predicted_error_m"] = float(pred[ok].mean())
    out["mean_actual_error_m"] = float(actual[ok].mean())
    out["ratio"] = out["mean_predicted_error_m"] / out["mean_actual_error_m"]
    out["p90_predicted_error_m"] = float(np.percentile(pred[ok], 90))
    out["p90_actual_error_m"] = float(np.percentile(actual[ok], 90))
    if np.ptp(pred[ok]) > 0:
        out["spearman"] = float(spearmanr(pred[ok], actual[ok]).statistic)
    if confidence.unreliable is not None:
        flags = confidence.unreliable[:len(actual)]
        for key, sel in (("actual_error_unreliable_m", flags), ("actual_error_reliable_m", ~flags)):
            if sel.any():
                out[key] = float(actual[sel].mean())
    return to_json(out)
