"""Is a method's predicted per-frame error honest? Check it, and calibrate it, on bench results.

``imuloco bench`` writes ``confidence-METHOD.npz`` for a method that predicts its own per-frame
error (:class:`imuloco.methods.base.Reconstruction`): per test frame the actual rms position
error (``actual_m``), the predicted one (``error_m``), the ``unreliable`` flag and the method's
uncalibrated ``score_*`` columns (for ``learned``: the network's sigma and the novelty of its
features), with ``clip``, ``content``, ``fold`` and ``seed``.

- :func:`check`: per content (or any label), the predicted rms error against the actual rms
  error (their ratio; the issue's target is within +-30 %), the share of frames flagged and the
  actual error of flagged and unflagged frames.
- :func:`fit`: a calibration ``error = exp(a) * prod_k score_k ** b_k``: least squares on the
  logarithms, then ``a`` moved so that the mean squared prediction equals the mean squared
  actual error over the data (an rms-honest prediction, not a geometric-mean one).
- :func:`crossfit`: every content's frames predicted by a calibration fitted on the *other*
  contents only: how the calibration does on motion it was not fitted on (the honest check on
  ``heldout-contents``, whose folds each leave their content out of training too).

Hand-written: a three-coefficient least-squares fit (numpy) is shorter than adapting a
general calibration library (scikit-learn's calibrators are for classifiers' probabilities).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from imuloco.errors import FormatError, InputError
from imuloco.io.npz import load_npz
from imuloco.methods.base import calibrated_error

TOLERANCE = 0.3  # the target: predicted rms error within +-30 % of the actual one
COLUMNS = ("actual_m", "error_m", "unreliable", "clip", "content", "fold", "seed")

Rows = dict[str, np.ndarray]


def load_rows(folders: Iterable[str | Path], method: str | None = None) -> Rows:
    """The per-frame rows of the ``confidence-METHOD.npz`` file in each bench result folder
    (``method`` in its file-name form, :func:`imuloco.lab.bench.slug`; None: the folder's
    only one), joined."""
    files = []
    for folder in folders:
        folder = Path(folder)
        pattern = f"confidence-{method}.npz" if method else "confidence-*.npz"
        found = sorted(folder.glob(pattern))
        if not found:
            raise InputError(f"{folder}: no {pattern} (write one with imuloco bench --out "
                             f"{folder} and a method that predicts its error, e.g. learned)")
        if len(found) > 1:
            raise InputError(f"{folder}: several methods' confidence files "
                             f"{[f.name for f in found]}: say which with --method")
        files += found
    parts = []
    for f in files:
        try:  # each array's declared shape checked against its size before it is read
            part = load_npz(f)
        except FormatError as e:
            raise FormatError(f, None, f"not a confidence file of imuloco bench or corrupted "
                              f"({e.message})") from None
        missing = [c for c in COLUMNS if c not in part]
        if missing:
            raise InputError(f"{f}: not a confidence file of imuloco bench (no {missing})")
        parts.append(part)
    keys = set.intersection(*(set(p) for p in parts))
    return {k: np.concatenate([p[k] for p in parts]) for k in sorted(keys)}


def score_names(rows: Rows) -> list[str]:
    """The uncalibrated score columns of ``rows``, without their ``score_`` prefix."""
    return sorted(k[len("score_"):] for k in rows if k.startswith("score_"))


def _design(rows: Rows, names: Sequence[str]) -> np.ndarray:
    logs = [np.log(np.maximum(rows[f"score_{n}"], 1e-6)) for n in names]
    return np.column_stack([np.ones(len(rows["actual_m"])), *logs])


def fit(rows: Rows, source: str) -> dict[str, Any]:
    """The calibration of ``rows`` (see the module docstring) as stored in a model file:
    ``{"coef": [a, b_1, ...], "scores": [names], "source": source}``."""
    names = score_names(rows)
    ok = np.all(np.isfinite(_design(rows, names)), axis=1) & (rows["actual_m"] > 0)
    if ok.sum() < 10 or not names:
        raise InputError(f"calibration needs per-frame scores of at least 10 frames; "
                         f"got {int(ok.sum())} frames with scores {names}")
    x = _design(rows, names)[ok]
    coef = np.linalg.lstsq(x, np.log(rows["actual_m"][ok]), rcond=None)[0]
    pred = np.exp(x @ coef)
    coef[0] += 0.5 * np.log(np.mean(rows["actual_m"][ok] ** 2) / np.mean(pred ** 2))
    return {"coef": [round(float(c), 6) for c in coef], "scores": names, "source": source}


def crossfit(rows: Rows, by: str = "content") -> np.ndarray:
    """Predicted error (N,) of every row by a calibration fitted on the rows of the other
    values of ``by`` (leave one group out)."""
    out = np.full(len(rows["actual_m"]), np.nan)
    for g in np.unique(rows[by]):
        inside = rows[by] == g
        cal = fit(_subset(rows, ~inside), f"all {by}s but {g}")
        out[inside] = calibrated_error(cal, {n: rows[f"score_{n}"][inside] for n in score_names(rows)})
    return out


def _subset(rows: Rows, mask: np.ndarray) -> Rows:
    return {k: v[mask] for k, v in rows.items()}


def check(rows: Rows, predicted: np.ndarray | None = None, by: str = "content",
          actual: str = "actual_m") -> list[dict[str, Any]]:
    """Per value of ``by`` and ``"all"``: frames, actual and predicted rms error (cm), their
    ratio and whether it is within :data:`TOLERANCE`, the share of frames flagged unreliable,
    and the actual rms error (cm) of flagged and of unflagged frames. ``predicted`` defaults to
    the rows' own ``error_m``; ``actual`` names the actual error's column
    (``actual_retargeted_m``: ``cross-dataset``'s against the truth on the training skeleton)."""
    pred = rows["error_m"] if predicted is None else predicted
    column = rows[actual]
    out = []
    for g in [*np.unique(rows[by]), "all"]:
        m = np.ones(len(pred), bool) if g == "all" else rows[by] == g
        flag, err = rows["unreliable"][m], column[m]
        actual = float(np.sqrt(np.mean(err ** 2)))
        predicted_rms = float(np.sqrt(np.mean(pred[m] ** 2)))

        ratio = predicted_rms / actual if actual > 0 else float("nan")
        out.append({by: str(g), "frames": int(m.sum()), "actual_cm": round(100 * actual, 2),
                    "predicted_cm": round(100 * predicted_rms, 2), "ratio": round(ratio, 3),
                    "within": bool(abs(ratio - 1) <= TOLERANCE),
                    "flagged_pct": round(100 * float(flag.mean()), 1),
                    "flagged_actual_cm": _rms_cm(err[flag]),
                    "unflagged_actual_cm": _rms_cm(err[~flag])})
    return out


def _rms_cm(err: np.ndarray) -> float | None:
    return round(100 * float(np.sqrt(np.mean(err ** 2))), 2) if len(err) else None


def markdown(table: list[dict[str, Any]], by: str = "content") -> str:
    """A check table as Markdown."""
    lines = [(f"| {by} | frames | actual rms cm | predicted rms cm | ratio | within ±30 % | "
              "flagged % | actual cm, flagged / unflagged |"),
             "|---|---:|---:|---:|---:|---|---:|---:|"]
    for r in table:
        pair = " / ".join("–" if v is None else f"{v:.2f}"
                          for v in (r["flagged_actual_cm"], r["unflagged_actual_cm"]))
        lines.append(f"| {r[by]} | {r['frames']} | {r['actual_cm']:.2f} | "
                     f"{r['predicted_cm']:.2f} | {r['ratio']:.2f} | "
                     f"{'yes' if r['within'] else 'no'} | {r['flagged_pct']:.1f} | {pair} |")
    return "\n".join(lines) + "\n"


def plot(rows: Rows, predictions: dict[str, np.ndarray], path: str | Path,
         by: str = "content") -> Path | None:
    """Predicted against actual rms error per ``by`` group, one marker series per prediction
    (a reliability plot; the diagonal is honest, the band +-30 %); None without matplotlib."""
    try:  # the [viz] extra's
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    fig, ax = plt.subplots(figsize=(5.5, 5))
    top = 0.0
    for label, pred in predictions.items():
        table = [r for r in check(rows, pred, by) if r[by] != "all"]
        x = [r["actual_cm"] for r in table]
        y = [r["predicted_cm"] for r in table]
        top = max(top, *x, *y)
        ax.scatter(x, y, label=label, zorder=3)
        for r, xi, yi in zip(table, x, y):
            ax.annotate(r[by], (xi, yi), fontsize=7, xytext=(3, 3), textcoords="offset points")
    line = np.array([0, top * 1.1])
    ax.plot(line, line, "k-", lw=0.8, zorder=2)
    ax.fill_between(line, line * (1 - TOLERANCE), line * (1 + TOLERANCE), color="0.9", zorder=0,
                    label=f"within ±{TOLERANCE:.0%}")
    ax.set_xlabel(f"actual rms error per {by}, cm")
    ax.set_ylabel(f"predicted rms error per {by}, cm")
    ax.legend(fontsize=8)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
