"""The body's path: where the body went, as a sensor's own physics measures it (issue 40).

One typed object (:class:`BodyPath`) that the path estimators (one module per placement in
:mod:`imuloco.paths`) return, the animation follows and the report shows. Floor frame: x is the
walker's initial heading, y to the left (right-handed with imuloco's Y up), origin at the start,
metres. A world point (X, Y, Z) with Y up maps to the floor as (Z, X) turned by minus the
initial heading (:func:`to_floor`): a walker facing +Z has its left on +X
(:mod:`imuloco.ops.heading`).
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import pairwise
from typing import TYPE_CHECKING, Protocol

import numpy as np

if TYPE_CHECKING:
    from imuloco.core.recording import Recording


@dataclass
class Footfall:
    foot: str            # "left" | "right"
    time_s: float        # the foot's contact (foot flat / mid-stance), seconds from the
    #                      recording's start
    xy: np.ndarray       # (2,) where it rests on the floor, metres, in the path's floor frame
    confidence: float    # 0..1, how sure the estimator is of this footfall's position


@dataclass
class Stride:
    foot: str
    start_s: float
    end_s: float
    length_m: float
    speed_mps: float
    confidence: float    # 0..1


@dataclass
class BodyPath:
    """Where the body went, as the sensor's own physics measures it.

    times_s : (T,) seconds; root_xy : (T, 2) the pelvis' horizontal position in metres in a floor
    frame whose x axis is the walker's initial heading (y to the left, right-handed, Y up as the
    rest of imuloco), origin at the start; heading_rad : (T,) a yaw in that frame, or None
    where the estimator does not know it (then only distances are trusted); which yaw,
    ``heading_kind`` says:

    - ``"facing"``: the body's facing (the hip line's normal), as the truth's
      :func:`imuloco.paths.truth.path_of_motion` reads it; the floor's x axis is the initial
      facing. The follower turns the hips to it.
    - ``"travel"``: the direction the pelvis travels (the path's own tangent), the floor's x
      axis the initial direction of travel: what every sensor estimator measures (a limb's
      path, or a trunk's yaw along which it walks). It is the facing only when walking
      forward: walking backwards they are 180 degrees apart, side-stepping 90, and no
      estimator tells these apart (each calibration assumes forward walking). The follower
      turns the body so that *the motion's own* direction of travel follows it, keeping the
      motion's own facing against it (:func:`imuloco.paths.follow.motion_heading`).

    footfalls, strides : as above (one foot's or both feet's, as the sensor sees them);
    source : the estimator's name ("foot-zupt", "shank-pivot", "lower-back-steps", ...);
    note : what the figures can and cannot be trusted for (shown to users).
    """
    times_s: np.ndarray
    root_xy: np.ndarray
    heading_rad: np.ndarray | None
    footfalls: list[Footfall]
    strides: list[Stride]
    source: str
    note: str
    heading_kind: str = "facing"  # "facing" | "travel" (the docstring)

    def distance_m(self) -> float:
        """Length of ``root_xy``'s polyline, metres."""
        if len(self.root_xy) < 2:
            return 0.0
        return float(np.linalg.norm(np.diff(self.root_xy, axis=0), axis=1).sum())

    @classmethod
    def from_report(cls, report: dict) -> BodyPath:
        """The path as a report's ``path`` keeps it (:func:`imuloco.paths.follow.path_report`:
        its track, footfalls and source; no strides): enough to draw it from above."""
        xy = np.asarray(report.get("track_xy") or np.zeros((0, 2)), dtype=float).reshape(-1, 2)
        falls = [Footfall(f["foot"], f["time_s"], np.asarray(f["xy"], float), f["confidence"])
                 for f in report.get("footfalls", [])]
        return cls(np.arange(len(xy), dtype=float), xy, None, falls, [],
                   report.get("source", ""), report.get("note", ""))

    def to_json(self) -> dict:
        """Summary + strides, for the report: ``source``, ``note``, ``duration_s``,
        ``distance_m``, ``end_xy``, ``strides`` (count), ``stride_length_m`` (mean),
        ``speed_mps`` (distance over duration), ``heading_known``, ``heading_kind``,
        ``footfalls`` and
        ``stride_rows`` (one dict per footfall / stride)."""
        dur = float(self.times_s[-1] - self.times_s[0]) if len(self.times_s) > 1 else 0.0
        lengths = [s.length_m for s in self.strides if np.isfinite(s.length_m)]
        dist = self.distance_m()
        end = self.root_xy[-1] if len(self.root_xy) else np.zeros(2)
        return {
            "source": self.source, "note": self.note, "duration_s": round(dur, 4),
            "distance_m": round(dist, 4),
            "end_xy": [round(float(v), 4) for v in end],
            "strides": len(self.strides),
            "stride_length_m": round(float(np.mean(lengths)), 4) if lengths else None,
            "speed_mps": round(dist / dur, 4) if dur > 0 else None,
            "heading_known": self.heading_rad is not None,
            "heading_kind": self.heading_kind,
            "footfalls": [{"foot": f.foot, "time_s": round(f.time_s, 4),
                           "xy": [round(float(v), 4) for v in f.xy],
                           "confidence": round(f.confidence, 3)} for f in self.footfalls],
            "stride_rows": [{"foot": s.foot, "start_s": round(s.start_s, 4),
                             "end_s": round(s.end_s, 4), "length_m": round(s.length_m, 4),
                             "speed_mps": round(s.speed_mps, 4),
                             "confidence": round(s.confidence, 3)} for s in self.strides],
        }


class PathEstimator(Protocol):
    """``name``; ``reads_all_sensors`` (optional, default False): the estimator reads every
    sensor of its kind in the recording itself (foot-zupt's two feet), so the registry does
    not fuse its paths (:func:`imuloco.paths.registry.fuse_paths`)."""

    name: str

    def estimate(self, rec: Recording, placement: str, height_m: float | None = None
                 ) -> BodyPath: ...


def to_floor(points: np.ndarray, origin: np.ndarray, heading0: float) -> np.ndarray:
    """World points (..., 3) (Y up) -> floor-frame points (..., 2) (module docstring).

    origin : (3,) world point mapped to (0, 0); heading0 : the initial heading, radians about
    +Y from +Z (:func:`imuloco.ops.heading.heading_from_hips`'s angle)."""
    p = np.asarray(points, float) - np.asarray(origin, float)
    c, s = np.cos(heading0), np.sin(heading0)
    z, x = p[..., 2], p[..., 0]
    return np.stack([c * z + s * x, -s * z + c * x], axis=-1)


def strides_from_footfalls(footfalls: list[Footfall], max_stride_s: float = 3.0
                           ) -> list[Stride]:
    """One stride per pair of successive footfalls of one foot, no more than ``max_stride_s``
    apart (a longer gap is a pause, not a stride): length the distance between their
    positions, confidence the lower of the two."""
    out = []
    for foot in ("left", "right"):
        own = sorted((f for f in footfalls if f.foot == foot), key=lambda f: f.time_s)
        for a, b in pairwise(own):
            dur = b.time_s - a.time_s
            if not 0 < dur <= max_stride_s:
                continue
            length = float(np.linalg.norm(np.asarray(b.xy) - np.asarray(a.xy)))
            out.append(Stride(foot, a.time_s, b.time_s, length, length / dur,
                              min(a.confidence, b.confidence)))
    out.sort(key=lambda s: (s.start_s, s.foot))
    return out
