"""A reconstruction's per-frame confidence, summarised for the reports a user reads.

Methods that know how sure they are (``learned``) return with their motion a per-frame
*predicted error*: the rms joint position error (metres, root-relative; lower is better) they
expect on that frame, and may flag frames as *unreliable*, where they do not know the motion
(:class:`imuloco.methods.base.Reconstruction`). :class:`Confidence` holds both beside the frame
rate; :meth:`Confidence.to_json` is the reports' ``confidence`` (the JSON report of ``imuloco
reconstruct``, ``batch``'s NAME.json, the demo's report.json). Methods that give
nothing (``ridge``, ...) are ``available: false`` with ``None`` values, never zeros. Whether
the predicted error is honest is checked, and calibrated, on bench results by
:mod:`imuloco.lab.confidence`.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from imuloco.errors import FormatError
from imuloco.phases.contacts import clean_mask, runs

MAX_SEGMENTS = 50  # the report lists at most this many unreliable segments (the longest)
MERGE_GAP_S = 0.5  # flagged runs less than this apart are one segment
MAX_BINS = 3600  # error_m_per_second: one value a second up to an hour, wider bins beyond


def _round(v: float | None, digits: int = 4) -> float | None:
    return None if v is None or not math.isfinite(v) else round(float(v), digits)


def flagged_segments(flags: np.ndarray, fps: float, merge_gap_s: float = MERGE_GAP_S
                     ) -> list[tuple[int, int]]:
    """Runs of flagged frames, those less than ``merge_gap_s`` apart merged.

    flags : ndarray of bool, shape (T,). Returns ``[(first, stop), ...]`` frame indices (stop
    exclusive), in time order."""
    gap = max(0, math.ceil(merge_gap_s * fps) - 1)  # unflagged runs shorter than merge_gap_s
    starts, stops, vals = runs(clean_mask(np.asarray(flags, dtype=bool), gap, 1))
    return [(int(a), int(b)) for a, b in zip(starts[vals], stops[vals])]


def binned_means(values: np.ndarray, size: int) -> np.ndarray:
    """Means of consecutive bins of ``size`` frames of ``values`` (T,), NaN left out (a bin
    with no finite value is NaN); shape (ceil(T / size),)."""
    v = np.asarray(values, dtype=np.float64)
    ok = np.isfinite(v)
    starts = np.arange(0, len(v), size)
    sums = np.add.reduceat(np.where(ok, v, 0.0), starts)
    counts = np.add.reduceat(ok.astype(np.int64), starts)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(counts > 0, sums / np.maximum(counts, 1), np.nan)


@dataclass
class Confidence:
    """A reconstruction's per-frame confidence (see the module docstring).

    error_m : ndarray, shape (T,), or None: predicted rms joint position error per frame,
        metres (NaN where the method could not say, e.g. in a gap of the recording).
    unreliable : ndarray of bool, shape (T,), or None: frames the method flags.
    fps : frames per second of both.
    note : how the method set them (or why there are none).
    """

    error_m: np.ndarray | None
    unreliable: np.ndarray | None
    fps: float
    note: str | None = None

    @classmethod
    def of(cls, reconstruction, fps: float, method: str = "the method") -> Confidence:
        """From a :class:`imuloco.methods.base.Reconstruction` of a method named ``method``."""
        err, flags, note = reconstruction.error_m, reconstruction.unreliable, reconstruction.note
        if err is None and flags is None and note is None:
            note = f"{method} gives no per-frame confidence"
        return cls(None if err is None else np.asarray(err, dtype=np.float64),
                   None if flags is None else np.asarray(flags, dtype=bool), float(fps), note)

    @classmethod
    def concatenate(cls, parts: list[Confidence]) -> Confidence:
        """Consecutive pieces' confidences as one (an array is None if any piece's is)."""
        def join(arrays):
            return None if not arrays or any(a is None for a in arrays) else np.concatenate(arrays)

        return cls(join([p.error_m for p in parts]), join([p.unreliable for p in parts]),
                   parts[0].fps, parts[0].note)

    @classmethod
    def from_report(cls, path: str | Path, frames: int, fps: float) -> Confidence:
        """Per-frame values back from a reconstruction report's ``confidence`` (the JSON file
        at ``path``, :meth:`to_json`) for its motion of ``frames`` frames at ``fps``: each bin's
        mean predicted error over its frames, flags over the listed segments (the report keeps
        the :data:`MAX_SEGMENTS` longest, so shorter ones beyond them are missing). A file
        that is not such a report raises :class:`imuloco.errors.FormatError` naming the field."""
        def fail(field: str, expected: str) -> FormatError:
            return FormatError(path, None, f"field {field}: expected {expected}")

        def number(v: Any) -> bool:
            return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)

        try:
            data = json.loads(Path(path).read_text(encoding="utf-8"))
        except UnicodeDecodeError:
            raise FormatError(path, None, "not a UTF-8 text file (expected a JSON report)"
                              ) from None
        except json.JSONDecodeError as e:
            raise FormatError(path, e.lineno, f"not JSON: {e.msg}") from None
        c = data.get("confidence") if isinstance(data, dict) else None
        if not isinstance(c, dict):
            raise fail("confidence", "an object (a report of `imuloco reconstruct --report` or "
                       "batch's NAME.json)")
        note = c.get("note") if isinstance(c.get("note"), str) else None
        err = flags = None
        per_s, bin_s = c.get("error_m_per_second"), c.get("error_m_bin_s", 1)
        if per_s is not None:
            if not isinstance(per_s, list) or not per_s or not all(
                    v is None or number(v) and v >= 0 for v in per_s):
                raise fail("confidence.error_m_per_second",
                           "a non-empty list of errors in metres (>= 0) or null")
            if not number(bin_s) or bin_s <= 0:
                raise fail("confidence.error_m_bin_s", "a positive number of seconds")
            means = np.array([np.nan if v is None else v for v in per_s], dtype=np.float64)
            with np.errstate(over="ignore"):  # a tiny bin: every frame in the last bin
                bins = np.floor(np.arange(frames) / fps / bin_s)
            err = means[np.clip(bins, 0, len(means) - 1).astype(np.int64)]
        segments = c.get("unreliable_segments")
        if segments is not None:
            if not isinstance(segments, list) or not all(
                    isinstance(s, list) and len(s) == 2 and all(map(number, s))
                    and 0 <= s[0] <= s[1] for s in segments):
                raise fail("confidence.unreliable_segments",
                           "a list of [start_s, end_s] with 0 <= start_s <= end_s")
            flags = np.zeros(frames, dtype=bool)
            end = frames / fps
            for a, b in segments:
                flags[round(min(a, end) * fps):round(min(b, end) * fps)] = True
        return cls(err, flags, float(fps), note)

    @property
    def available(self) -> bool:
        """Whether the method gave a confidence (a predicted error, unreliable flags or both)."""
        return self.error_m is not None or self.unreliable is not None

    def scaled(self, factor: float) -> Confidence:
        """The same with lengths times ``factor`` (the motion scaled to a wearer's height)."""
        err = None if self.error_m is None else self.error_m * factor
        return Confidence(err, self.unreliable, self.fps, self.note)

    def sliced(self, start: int, stop: int) -> Confidence:
        """Frames ``start:stop``."""
        def cut(a):
            return None if a is None else a[start:stop]

        return Confidence(cut(self.error_m), cut(self.unreliable), self.fps, self.note)

    @property
    def mean_error_m(self) -> float | None:
        """Mean predicted error over the frames, metres."""
        e = self._finite()
        return float(e.mean()) if e is not None and len(e) else None

    @property
    def unreliable_fraction(self) -> float | None:
        """Share of frames flagged unreliable (0-1)."""
        if self.unreliable is None or not len(self.unreliable):
            return None
        return float(np.count_nonzero(self.unreliable) / len(self.unreliable))

    def _finite(self) -> np.ndarray | None:
        return None if self.error_m is None else self.error_m[np.isfinite(self.error_m)]

    def to_json(self) -> dict[str, Any]:
        """The report's ``confidence``: ``available``, ``mean_error_m``, ``p90_error_m`` and
        ``max_error_m`` (metres), ``unreliable_fraction``, ``unreliable_segments`` (``[[start_s,
        end_s], ...]``, runs of flagged frames less than :data:`MERGE_GAP_S` apart merged, the
        :data:`MAX_SEGMENTS` longest in time order), ``unreliable_segments_total`` (their number
        before the cut), ``error_m_per_second`` (mean predicted error of each ``error_m_bin_s``
        seconds: 1 up to an hour, wider beyond so that at most :data:`MAX_BINS` values) and
        ``note``; ``None`` where the method gives nothing."""
        e = self._finite()
        some = e is not None and len(e) > 0
        out: dict[str, Any] = {
            "available": self.available,
            "mean_error_m": _round(self.mean_error_m),
            "p90_error_m": _round(float(np.percentile(e, 90))) if some else None,
            "max_error_m": _round(float(e.max())) if some else None,
            "unreliable_fraction": _round(self.unreliable_fraction),
            "unreliable_segments": None, "unreliable_segments_total": None,
            "error_m_per_second": None, "error_m_bin_s": None, "note": self.note,
        }
        if self.unreliable is not None:
            segs = flagged_segments(self.unreliable, self.fps)
            keep = sorted(sorted(segs, key=lambda s: s[0] - s[1])[:MAX_SEGMENTS])
            out["unreliable_segments"] = [[round(a / self.fps, 3), round(b / self.fps, 3)]
                                          for a, b in keep]
            out["unreliable_segments_total"] = len(segs)
        if self.error_m is not None and len(self.error_m):
            seconds = len(self.error_m) / self.fps
            bin_s = max(1, math.ceil(seconds / MAX_BINS))
            means = binned_means(self.error_m, max(1, round(bin_s * self.fps)))
            out["error_m_per_second"] = [_round(v) for v in means]
            out["error_m_bin_s"] = bin_s
        return out
