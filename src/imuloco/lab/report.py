"""``results.md``: the benchmark's records as Markdown tables, with plots beside them.

Plots need matplotlib (the ``viz`` extra); without it the tables are written with a note.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from imuloco.io.atomic import atomic_write_text

# (key, column title, format) of the summary table
COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("mpjpe_cm", "MPJPE cm", "{:.2f}"),
    ("rmse_cm", "RMSE cm", "{:.2f}"),
    ("upper_cm", "upper cm", "{:.2f}"),
    ("lower_cm", "lower cm", "{:.2f}"),
    ("angle_deg", "D_E deg", "{:.2f}"),
    ("dpv", "D_pv m²", "{:.3f}"),
    ("jitter", "jitter m/s³", "{:.0f}"),
    ("foot_skate_cm_s", "skate cm/s", "{:.1f}"),
    ("root_speed_err_cm_s", "speed err cm/s", "{:.1f}"),
    ("path_err_cm", "path err cm", "{:.1f}"),
)
# the animation's path against the truth's (issue 40), mean absolute errors over clips, and
# the animation's pose (MPJPE, skate)
PATH_COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("path_distance_ratio", "distance ratio", "{:.2f}"),
    ("path_distance_mae_pct", "distance MAE %", "{:.1f}"),
    ("path_stride_mae_pct", "stride MAE %", "{:.1f}"),
    ("path_stride_mae_m", "stride MAE m", "{:.3f}"),
    ("path_end_point_error_pct", "end-point err %", "{:.1f}"),
    ("animation_mpjpe_cm", "MPJPE cm", "{:.2f}"),
    ("animation_foot_skate_cm_s", "skate cm/s", "{:.1f}"),
    ("foot_skate_gt_cm_s", "truth's skate cm/s", "{:.1f}"),
)
# the same of the method's raw root (no path follower)
RAW_PATH_COLUMNS: tuple[tuple[str, str, str], ...] = tuple(
    (key.replace("path_", "path_raw_", 1), title, fmt) for key, title, fmt in PATH_COLUMNS[:5])
# cross-dataset: against the ground truth retargeted onto the training skeleton
RETARGETED_COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("mpjpe_retargeted_cm", "MPJPE cm", "{:.2f}"),
    ("upper_retargeted_cm", "upper cm", "{:.2f}"),
    ("lower_retargeted_cm", "lower cm", "{:.2f}"),
    ("legs_retargeted_cm", "legs cm", "{:.2f}"),
    ("arms_retargeted_cm", "arms cm", "{:.2f}"),
    ("trunk_retargeted_cm", "trunk cm", "{:.2f}"),
)
# the body-part groups (legs, arms, trunk) of imuloco.core.bodymap.PART_GROUPS
GROUP_COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("legs_cm", "legs cm", "{:.2f}"),
    ("arms_cm", "arms cm", "{:.2f}"),
    ("trunk_cm", "trunk cm", "{:.2f}"),
)
COST_COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("train_s", "train s", "{:.1f}"),
    ("offline_fps", "offline fps", "{:.0f}"),
    ("online_latency_ms_p50", "online ms p50", "{:.3f}"),
    ("online_latency_ms_p99", "online ms p99", "{:.3f}"),
    ("online_delay_ms", "online delay ms", "{:.0f}"),
    ("model_bytes", "model size", "{}"),
)


def _fmt(value: Any, fmt: str, key: str = "") -> str:
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return "–"
    if key == "model_bytes":
        return _size(int(value))
    return fmt.format(value)


def _size(n: int) -> str:
    for unit in ("B", "kB", "MB", "GB"):
        if n < 1000 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1000
    return str(n)


def table(rows: Sequence[dict[str, Any]], columns: Sequence[tuple[str, str, str]],
          first: Sequence[tuple[str, str]] = (("method", "method"),)) -> str:
    """A Markdown table: the ``first`` keys as text, then ``columns`` formatted."""
    head = [t for _, t in first] + [t for _, t, _ in columns]
    lines = ["| " + " | ".join(head) + " |",
             "|" + "|".join(["---"] * len(first) + ["---:"] * len(columns)) + "|"]
    for r in rows:
        cells = [str(r.get(k, "")) for k, _ in first]
        cells += [_fmt(r.get(k), f, k) + ("" if r.get(f"{k}_std") is None
                                           else " ± " + _fmt(r[f"{k}_std"], f, k))
                  for k, _, f in columns]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def by_type_table(records: Sequence[dict[str, Any]], key: str = "mpjpe_cm") -> str:
    """Methods as rows, motion types as columns (like Mousas 2017 Table 3), one metric."""
    methods = list(dict.fromkeys(r["method"] for r in records))
    types = list(dict.fromkeys(r["motion_type"] for r in records))
    lookup = {(r["method"], r["motion_type"]): r for r in records}
    head = "| method | " + " | ".join(types) + " |"
    sep = "|---|" + "|".join(["---:"] * len(types)) + "|"
    rows = [head, sep]
    for m in methods:
        cells = [_fmt(lookup.get((m, t), {}).get(key), "{:.2f}")
                 + ("" if lookup.get((m, t), {}).get(f"{key}_std") is None
                    else " ± " + _fmt(lookup[(m, t)][f"{key}_std"], "{:.2f}"))
                 for t in types]
        rows.append(f"| {m} | " + " | ".join(cells) + " |")
    return "\n".join(rows)


def write_report(
    records: Sequence[dict[str, Any]],
    out: Path,
    per_joint: dict[str, np.ndarray] | None = None,
    joint_names: Sequence[str] | None = None,
    curves: dict[str, np.ndarray] | None = None,
    curve_clip: str = "",
    fps: float = 30.0,
) -> Path:
    """Write ``out/results.md`` (and ``error_per_joint.png``, ``error_over_time.png``).

    Parameters
    ----------
    records : the benchmark records (see :func:`imuloco.lab.bench.run_bench`).
    per_joint : method -> mean heading-frame position error per joint, cm, shape (J,).
    joint_names : J names for the per-joint plot.
    curves : method -> per-frame RMSE, cm, shape (T,), of the one clip ``curve_clip``.
    """
    out.mkdir(parents=True, exist_ok=True)
    first = records[0] if records else {}
    totals = [r for r in records if r["motion_type"] == "all"]
    lines = [
        "# Benchmark results", "",
        (f"Split `{first.get('split')}`, noise `{first.get('noise')}`, placements "
         f"`{', '.join(first.get('placements', []))}`, data `{first.get('data')}`, protocol "
         f"version {first.get('protocol_version')}, training seed(s) "
         f"{', '.join(map(str, first.get('seeds', [first.get('seed')])))} (± is the spread "
         "over seeds); "
         f"{totals[0]['n_clips'] if totals else '?'} test clips, "
         f"{totals[0]['n_frames'] if totals else '?'} frames."), "",
        ("Errors are heading-frame joint positions relative to the pelvis (every joint but the "
         "root); RMSE is per frame then averaged (Eom et al. 2014); D_E and D_pv as Tautges et "
         "al. 2008; skate = horizontal foot speed during ground-truth contact; speed and path "
         "errors over 2 s windows aligned at their start. Frame-weighted means over test "
         "clips."), "",
        "## All test clips", "",
        table(totals, COLUMNS), "",
        "## Cost", "",
        table(totals, COST_COLUMNS), "",
        "## MPJPE (cm) by motion type", "",
        by_type_table(records, "mpjpe_cm"), "",
        "## RMSE (cm) by motion type", "",
        by_type_table(records, "rmse_cm"), "",
        "## Every metric by motion type", "",
        table(records, COLUMNS, (("method", "method"), ("motion_type", "motion type"),
                                 ("n_clips", "clips"), ("n_frames", "frames"))), "",
    ]
    if any(r.get("path_distance_ratio") is not None for r in records):
        lines += [
            "## The path: where the body went", "",
            ("The path of the animation `imuloco reconstruct` writes (the method's output "
             "following the placement's path estimator) — pelvis averaged over a step, "
             "strides between its feet's mid-stances — against the ground truth's: the "
             "distance ratio's mean, mean absolute errors of the distance walked and the mean "
             "stride length per clip, and the end-point error in per cent of the distance "
             "walked; the animation's MPJPE and foot skate beside the truth's skate."), "",
            table(records, PATH_COLUMNS, (("method", "method"),
                                          ("motion_type", "motion type"))), "",
            "The same of the method's raw root (before the path follower):", "",
            table(records, RAW_PATH_COLUMNS, (("method", "method"),
                                              ("motion_type", "motion type"))), ""]
    lines += group_section(records)
    if any(r.get("mpjpe_retargeted_cm") is not None for r in records):
        lines += [
            "## Against the ground truth retargeted onto the training skeleton", "",
            ("The test clips are on another skeleton: the errors above compare body parts "
             "with the reconstruction scaled by the leg-length ratio, and other proportions "
             "keep even a perfect motion above zero there. Here the reference is the ground "
             "truth retargeted onto the training skeleton (as training clips of other rigs "
             "are), whose floor is zero."), "",
            table(records, RETARGETED_COLUMNS, (("method", "method"),
                                                ("motion_type", "motion type"))), ""]
    lines += _plots(out, per_joint, joint_names, curves, curve_clip, fps)
    path = out / "results.md"
    atomic_write_text(path, "\n".join(lines) + "\n")
    return path


def group_section(records: Sequence[dict[str, Any]], baseline: str = "mean") -> list[str]:
    """``results.md``'s body-part section: legs, arms and trunk per method and motion type,
    and, when ``baseline`` (the mean pose) was run beside, where a method is worse than it."""
    rows = [r for r in records if any(r.get(k) is not None for k, _, _ in GROUP_COLUMNS)]
    if not rows:
        return []
    lines = ["## Body parts: legs, arms, trunk", "",
             ("Mean position error of each group of canonical parts (legs: hips to toes; arms: "
              "shoulders to wrists; trunk: spine to head), heading frame at the pelvis."), "",
             table(rows, GROUP_COLUMNS, (("method", "method"), ("motion_type", "motion type"))),
             ""]
    base = {r["motion_type"]: r for r in rows if r["method"] == baseline}
    if not base:
        return lines
    worse = [f"{r['method']} {key[:-3]} on {r['motion_type']} ({r[key]:.2f} against "
             f"{base[r['motion_type']][key]:.2f} cm)"
             for r in rows if r["method"] != baseline and r["motion_type"] in base
             for key, _, _ in GROUP_COLUMNS
             if r.get(key) is not None and base[r["motion_type"]].get(key) is not None
             and r[key] > base[r["motion_type"]][key]]
    lines += [f"Against the mean pose (`{baseline}`): "
              + ("every group of every method is at least as good." if not worse else
                 f"{len(worse)} group(s) worse: " + "; ".join(worse) + "."), ""]
    return lines


def _plots(out: Path, per_joint, joint_names, curves, curve_clip: str, fps: float) -> list[str]:
    if not per_joint and not curves:
        return []
    try:  # the [viz] extra's
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return ["## Plots", "", ("_Plots skipped: matplotlib is not installed "
                                 "(`pip install 'imuloco[viz]'`)._"), ""]
    lines = ["## Plots", ""]
    if per_joint and joint_names is not None:
        names = list(joint_names)[1:]
        x = np.arange(len(names))
        width = 0.8 / len(per_joint)
        fig, ax = plt.subplots(figsize=(max(8, 0.45 * len(names)), 4))
        for k, (m, err) in enumerate(per_joint.items()):
            ax.bar(x + (k - (len(per_joint) - 1) / 2) * width, np.asarray(err)[1:], width,
                   label=m)
        ax.set_xticks(x, names, rotation=60, ha="right")
        ax.set_ylabel("mean position error (cm)")
        ax.set_title("Error per joint (heading frame, relative to the pelvis)")
        ax.legend()
        fig.tight_layout()
        fig.savefig(out / "error_per_joint.png", dpi=100)
        plt.close(fig)
        lines += ["![error per joint](error_per_joint.png)", ""]
    if curves:
        fig, ax = plt.subplots(figsize=(8, 3.5))
        for m, c in curves.items():
            ax.plot(np.arange(len(c)) / fps, c, label=m, lw=1.2)
        ax.set_xlabel("time (s)")
        ax.set_ylabel("RMSE of joint positions (cm)")
        ax.set_title(f"Error over time, clip {curve_clip} (cf. Eom et al. 2014 Fig. 9)")
        ax.legend()
        fig.tight_layout()
        fig.savefig(out / "error_over_time.png", dpi=100)
        plt.close(fig)
        lines += ["![error over time](error_over_time.png)", ""]
    return lines
