"""A reconstruction's report in words and pictures: ``NAME.md`` with plots beside it, from
the JSON report (:meth:`imuloco.app.pipeline.ReconstructionReport.to_json`, ``batch``'s
NAME.json, ``--piece-seconds``' report) and the demo's ``report.md``.

Everything here reads the JSON dict only, so a report written earlier reads the same.
:func:`write_summary` draws the plots with :mod:`imuloco.viz.gaitplots` (the ``[viz]`` extra;
without matplotlib the markdown says so and has no pictures).
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from imuloco.io.atomic import atomic_write, check_outputs
from imuloco.sensors.placement import PRESETS

log = logging.getLogger(__name__)

# What a predicted error looks like, with the measured anchors it is compared with
# (docs/results/README.md: heldout-styles, one phone at the right ankle; the shipped shin
# model's 3.40 cm is the README's "as shipped" row), and how it is calibrated
# (docs/lab-notes.md, "Results": the ensemble's spread, tenth and fourteenth rounds).
ERROR_SCALE = [
    ("**What the predicted error means.** For scale, on simulated lab walks of styles the "
     "model never saw: about 3 cm is the shipped shin model (3.4), 5 cm a plain regression "
     "(`ridge`, 5.5), 10 cm one average pose held still (`mean`, 9.5 cm). At 20 cm the pose "
     "is a guess, though the rhythm of the legs may still be right. The prediction is "
     "calibrated on motion the model never saw (within ±30 % of the actual error on 6 of 8 "
     "left-out kinds of motion; the turns read 1.4 times theirs)."),
    "",
    ("**Why it can be high with few frames flagged.** A frame is flagged only where the "
     "signal lies farther from all training motion than 99 % of unseen lab frames do. A real "
     "phone's signal sits a little apart all along (a strap damps and rolls it; the model "
     "learned from simulated sensors), which raises the predicted error everywhere without "
     "crossing that line: the real RealWorld shin walk reads 17.9 cm with 2.7 % of its frames "
     "flagged, and 9 of its 10 flagged stretches start at gaps in the phone's samples."),
]

STRIDE_EVIDENCE = "docs/results/real/shin-stride/README.md"


def _fmt(v: Any) -> str:
    return "–" if v is None else (f"{v:.3g}" if isinstance(v, float) else str(v))

def _value(v: Any) -> str:
    """A table's number: whole above 100 (1061 steps, not 1.06e+03), else 3 digits."""
    return f"{v:.0f}" if isinstance(v, float) and abs(v) >= 100 else _fmt(v)


def _cm(v: float | None) -> str:
    return "–" if v is None else f"{100 * v:.2f}"


def confidence_markdown(report: dict[str, Any]) -> list[str]:
    """A report's lines on the method's confidence: its predicted error, beside the actual one
    where a ground truth exists (the demo's ``confidence_check``), and what it means
    (:data:`ERROR_SCALE`)."""
    conf = report.get("confidence") or {}
    lines = ["## Confidence (the method's predicted error)", ""]
    if not conf.get("available"):
        return [*lines, f"None: {conf.get('note') or 'the method gives no confidence'}.", ""]
    check = report.get("confidence_check")
    frac = conf.get("unreliable_fraction")
    if check is None:  # no ground truth: what the method predicts, per frame and over time
        lines += [
            ("The method predicts, per frame, its own rms joint position error (relative to "
             "the pelvis): "
             f"mean {_cm(conf.get('mean_error_m'))} cm, 90th percentile "
             f"{_cm(conf.get('p90_error_m'))} cm, worst {_cm(conf.get('max_error_m'))} cm. "
             "Frames flagged unreliable: "
             + ("not flagged by this method" if frac is None else
                f"{100 * frac:.1f} % in {conf.get('unreliable_segments_total', 0)} "
                "stretch(es)") + "."),
            "",
        ]
    else:
        lines += [
            ("The method predicts, per frame, its rms joint position error (relative to the "
             "pelvis); here it is set beside the actual error against the ground truth "
             "(`errors.png` draws both per frame; the viewer shows it and marks flagged "
             "frames)."),
            "",
            "| | predicted | actual |",
            "|---|---:|---:|",
            (f"| mean rms joint position error (cm) | {_cm(check.get('mean_predicted_error_m'))} "
             f"| {_cm(check.get('mean_actual_error_m'))} |"),
            (f"| 90th percentile (cm) | {_cm(check.get('p90_predicted_error_m'))} "
             f"| {_cm(check.get('p90_actual_error_m'))} |"),
            "",
            (f"Predicted / actual: {_fmt(check.get('ratio'))} (1 is calibrated, below 1 "
             f"over-confident); Spearman rank correlation over frames: "
             f"{_fmt(check.get('spearman'))}. Frames flagged unreliable: "
             + ("not flagged by this method" if frac is None else
                f"{100 * frac:.1f} % (actual error there "
                f"{_cm(check.get('actual_error_unreliable_m'))} cm, elsewhere "
                f"{_cm(check.get('actual_error_reliable_m'))} cm)") + "."),
        ]
    lines += [f"Note: {(conf.get('note') or '–').rstrip('.')}.", "", *ERROR_SCALE, ""]
    return lines


def demo_markdown(report: dict[str, Any]) -> str:
    """The short human-readable report of :func:`demo`."""
    calib = "; ".join(
        f"{c['placement']} sensor turned {c['rotation_deg']:.1f} deg from the segment's frame "
        f"(up axis from {c['up_from']}, {c['swings']} strides found)"
        for c in report.get("calibration", [])) or "not run"
    lines = [
        "# imuloco demo",
        "",
        (f"Clip `{report['clip']}` of the bundled sample; a phone on the right ankle simulated "
         "with phone noise (`recording.csv`), then imported, calibrated and reconstructed as "
         "`imuloco reconstruct recording.csv` would."),
        "",
        f"- Model: {report['model']}.",
        f"- Calibration: {calib}.",
        (f"- Reconstruction: {report['motion']['frames']} frames at "
         f"{report['motion']['fps']:g} fps; took {report['seconds']} s end to end (rendering "
         "included)."),
        "",
        "## Metrics (reconstruction against the ground truth)",
        "",
        "| metric | value |",
        "|---|---:|",
        *[f"| {k} | {_fmt(v)} |" for k, v in report["metrics"].items()],
        "",
        "## Gait parameters",
        "",
        "| parameter | ground truth | reconstruction |",
        "|---|---:|---:|",
        *[f"| {k} | {_fmt(report['gait_ground_truth'][k])} | {_fmt(v)} |"
          for k, v in report["gait"].items()],
        f"| cadence of the raw signal (Welch) | | {_fmt(report['signal_cadence_spm'])} |",
        *[f"| {k} | {_fmt(report['plausibility_ground_truth'][k])} | "
          f"{_fmt(v)} |" for k, v in report["plausibility"].items() if k.endswith("_swing_deg")],
        f"| shank swing of the raw signal (deg) | | {_fmt(report['signal_swing_deg'])} |",
        "",
        *confidence_markdown(report),
        "## Files",
        "",
        ("`reconstruction.bvh` (opens in Blender), `demo.mp4` / `demo.gif` (ground truth "
         "left, reconstruction right), `demo.html` (interactive viewer, works offline), "
         "`signals.png`, `phases.png`, `errors.png`, `report.json`."),
        "",
    ]
    return "\n".join(lines)


def caveats(report: dict[str, Any]) -> list[str]:
    """Plain-language caveats of the method for this report's placement and model, each with
    the evidence it rests on (measured figures; the files that hold them)."""
    placement = report.get("placement", "")
    preset = PRESETS.get(placement)
    out = []
    if preset is not None and preset.on_shank:
        out.append(
            "**A shin sensor's gait is the model's.** Cadence and stance come from the "
            "reconstructed legs and agree with the signal on a real shin walk (cadence within "
            "1 % of the sensor's own rhythm, stance 62 / 55 %). Stride length and speed do "
            "not have that check: on the RealWorld shin walk the model reads 0.80 m a stride "
            "where the shank's own swing (79° by its gyroscope, model-free) suggests at least "
            "1.15 m, and the leg without the phone swings 44° against 66°. Trust the cadence "
            "and the rhythm; use stride and speed to compare walks of one person, not as "
            f"metres ({STRIDE_EVIDENCE}). This walk's own check is in the gait note below.")
    elif placement in ("right_foot", "left_foot"):
        out.append(
            "**A shoe sensor measures gait itself** (its zero-velocity track, gaitmap): on 110 "
            "real trials of ipol-gait steps are 1.4-1.6 % off, cadence 0.8-0.9 %, stride "
            "4.2-4.6 %, speed 3.5-4.1 %; the other foot's stance is not measured. The "
            "animation's own gait is the model's (stride 7.2-8.7 % off on the same trials; "
            "docs/results/real/README.md, docs/results/real/foot-model.md).")
    elif placement == "lower_back":
        out.append(
            "**A lower-back sensor measures gait itself** (Mobilise-D's pipeline, mobgap; the "
            "pendulum needs the walker's height, `--height`): cadence 1.3 % off on ipol-gait, "
            "2.6 % on mobilise-d-lab, stride and speed 8.6-15 %; slow shuffling and turning "
            "strides read too long. The animation keeps the rhythm but its strides are short "
            "(docs/results/real/README.md, docs/results/real/lower-back-model.md).")
    if "fitted" in str(report.get("model", "")) and "on the fly" in str(report.get("model", "")):
        out.append(
            f"**No shipped model for `{placement}`**: {report['model']}. On simulated "
            "held-out styles of the bundled sample such a fit is 6-8 cm off (MPJPE) with feet "
            "sliding 94-188 cm/s (docs/results/placements/): a rough animation, and its gait "
            "is not to be trusted.")
    model_gait = str(report.get("gait_source", "")).startswith("the reconstructed motion")
    if report.get("height_m") is None and model_gait:
        out.append("**Lengths and speeds are on the model's skeleton** (1.63 m tall for the "
                   "shipped models); `--height METRES` puts them in the wearer's proportions.")
    return out


def _gait_lines(report: dict[str, Any]) -> list[str]:
    gait = report.get("gait") or {}
    rows = (("steps", "steps", ""), ("cadence_spm", "cadence", "steps/min"),
            ("cadence_rhythm_spm", "cadence from the legs' rhythm", "steps/min"),
            ("stride_length_m", "stride length", "m"), ("speed_mps", "speed", "m/s"),
            ("left_stance_pct", "stance, left foot", "%"),
            ("right_stance_pct", "stance, right foot", "%"),
            ("double_support_pct", "double support", "%"))
    lines = ["## Gait", "", f"Source: {report.get('gait_source', '–')}.", "",
             "| parameter | value |", "|---|---:|"]
    lines += [f"| {label} ({unit}) | {_value(gait.get(key))} |" if unit else
              f"| {label} | {_value(gait.get(key))} |" for key, label, unit in rows if key in gait]
    if report.get("signal_cadence_spm") is not None:
        lines.append(f"| cadence of the raw signal (steps/min) | "
                     f"{_value(report['signal_cadence_spm'])} |")
    p = report.get("plausibility") or {}
    if report.get("signal_swing_deg") is not None:
        lines += [(f"| shank swing a stride, right / left (deg) | "
                  f"{_value(p.get('right_shank_swing_deg'))} / "
                  f"{_value(p.get('left_shank_swing_deg'))} |"),
                  f"| shank swing of the raw signal (deg) | {_value(report['signal_swing_deg'])} |"]
    if p.get("foot_skate_cm_s") is not None:
        lines.append(f"| foot skate (cm/s) | {_value(p['foot_skate_cm_s'])} |")
    note = report.get("gait_note") or (
        "measured by the sensor itself (see the source above and the caveats)"
        if not str(report.get("gait_source", "")).startswith("the reconstructed motion")
        else "–")
    lines += ["", f"Gait note: {note}", ""]
    return lines


def summary_markdown(report: dict[str, Any], name: str = "recording",
                     plots: dict[str, str] | None = None, plot_note: str | None = None) -> str:
    """The readable summary of a reconstruction's JSON ``report``; ``plots`` maps a plot's
    kind (``path``, ``strides``, ``symmetry``, ``contacts``, ``error``) to its file name
    beside the markdown; ``plot_note`` says why there are none."""
    plots = plots or {}
    m = report.get("motion") or {}
    rec = report.get("recording") or {}
    calib = "; ".join(
        f"{c['placement']} sensor turned {c['rotation_deg']:.1f} deg from the segment's frame "
        f"(up axis from {c['up_from']}, {c['still_s']} s standing still, {c['swings']} strides)"
        for c in report.get("calibration") or []) or "not run"
    captions = {
        "path": "The path walked, seen from above, with the footfalls.",
        "strides": "Stride length and cadence of every stride over time (dots), with their "
                   "running median (lines): a steady walk is a flat line.",
        "symmetry": "Left against right: medians with their interquartile range (for a shin "
                    "sensor, each reconstructed shank's swing against the sensor's own, "
                    "dashed).",
        "contacts": "When each foot is down during the first strides (the gait diagram).",
        "error": "The model's predicted error over time; shaded: flagged unreliable.",
    }
    lines = [f"# {name}: reconstruction summary", "",
             (f"- Recording: {', '.join(map(str, rec.get('files', []))) or '–'} "
             f"({rec.get('format', '–')}, {_fmt(rec.get('source_rate_hz'))} Hz, "
             f"{_fmt(rec.get('duration_s'))} s)."),
             (f"- Placement: `{report.get('placement', '–')}`; "
              f"model: {report.get('model', '–')}."),
             f"- Calibration: {calib}.",
             (f"- Motion: {m.get('frames', '–')} frames at {_fmt(m.get('fps'))} fps; wearer's "
             f"height: {_fmt(report.get('height_m'))} m."), ""]
    cautions = caveats(report)
    if cautions:
        lines += ["## Read this first", "", *[f"- {c}" for c in cautions], ""]
    lines += _gait_lines(report)
    shown = [k for k in captions if k in plots]
    if shown or plot_note:
        lines += ["## Plots", ""]
        for k in shown:
            lines += [f"![{k}]({plots[k]})", "", captions[k], ""]
        if plot_note:
            lines += [plot_note, ""]
    lines += confidence_markdown(report)
    near = flagged_near_gaps(report)
    if near is not None:
        lines += [(f"Here {near[0]} of the {near[1]} flagged stretches listed start within "
                  f"{GAP_MARGIN_S:g} s of a gap in the recording's samples (the report's "
                  "`recording.gaps`): look at the log there before at the motion."), ""]
    return "\n".join(lines)


GAP_MARGIN_S = 2.0


def flagged_near_gaps(report: dict[str, Any]) -> tuple[int, int] | None:
    """(how many of the report's unreliable segments start within :data:`GAP_MARGIN_S` of a
    gap in the recording, how many segments are listed); None without both."""
    segments = (report.get("confidence") or {}).get("unreliable_segments") or []
    gaps = (report.get("recording") or {}).get("gaps") or []
    if not segments or not gaps:
        return None
    near = sum(any(a - GAP_MARGIN_S <= start <= b + GAP_MARGIN_S for a, b in gaps)
               for start, _ in segments)
    return near, len(segments)


def summary_paths(md_path: str | Path) -> dict[str, Path]:
    """The files :func:`write_summary` may write for ``md_path``: itself (``"md"``) and one
    PNG per plot beside it (``NAME-strides.png``, ...)."""
    md = Path(md_path)
    return {"md": md, **{k: md.with_name(f"{md.stem}-{k}.png")
                         for k in ("path", "strides", "symmetry", "contacts", "error")}}


def write_summary(report: dict[str, Any], md_path: str | Path, overwrite: bool = False,
                  name: str | None = None) -> list[Path]:
    """Write ``md_path`` (:func:`summary_markdown`) and its plots beside it; returns the
    files written. Existing files are refused unless ``overwrite`` (checked before any is
    written)."""
    paths = summary_paths(md_path)
    check_outputs(paths.values(), overwrite)
    written, plots, note = [], {}, None
    try:
        from imuloco.viz import gaitplots  # the [viz] extra: matplotlib
        from imuloco.viz import plots as motion_plots  # beside it: both or neither
    except ModuleNotFoundError as e:
        if e.name != "matplotlib":
            raise
        note = "No plots: matplotlib is not installed (`pip install 'imuloco[viz]'`)."
    else:
        strides = report.get("strides") or []
        draw = {}
        if report.get("path") is not None and hasattr(motion_plots, "plot_path"):
            draw["path"] = lambda p: motion_plots.plot_path(report["path"], p, overwrite=True)
        if strides:
            p = report.get("plausibility") or {}
            swing = ({f: p.get(f"{f}_shank_swing_deg") for f in ("left", "right")}
                     if report.get("signal_swing_deg") is not None else None)
            draw["strides"] = lambda path: gaitplots.plot_strides(strides, path, overwrite=True)
            draw["symmetry"] = lambda path: gaitplots.plot_symmetry(
                strides, path, swing, report.get("signal_swing_deg"), overwrite=True)
            draw["contacts"] = lambda path: gaitplots.plot_contacts(strides, path,
                                                                    overwrite=True)
        elif "pieces" in report and "strides" not in report:
            note = "No stride plots: a reconstruction in pieces keeps no per-stride rows."
        else:
            note = "No stride plots: no stride was found."
        conf = report.get("confidence") or {}
        if conf.get("error_m_per_second"):
            draw["error"] = lambda path: gaitplots.plot_predicted_error(
                conf["error_m_per_second"], conf.get("error_m_bin_s", 1),
                path, conf.get("unreliable_segments", []), overwrite=True)
        for kind, plot in draw.items():
            written.append(plot(paths[kind]))
            plots[kind] = paths[kind].name
    with atomic_write(paths["md"], "w") as f:
        f.write(summary_markdown(report, name or paths["md"].stem, plots, note))
    return [paths["md"], *written]
