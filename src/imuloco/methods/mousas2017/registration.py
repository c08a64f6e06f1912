"""Segmentation into gait phases (Mousas 2017 sec. 4.2) and registration (sec. 4.3).

Segmentation uses :func:`imuloco.phases.gait_phases` (Table 1 from heel/toe contacts and ankle
crossing events). Choices where the paper is silent:

- the first and last segment of every clip are dropped: they are cut by the clip's ends, not by
  a gait event, so they are partial phases that registration would stretch onto whole ones;
- a segment longer than ``max_len`` frames (standing, or a hop or jump whose contacts do not
  change for a while) is cut further at the minima and maxima of the root speed, the
  "speed (minimum and maximum)" segmentation that the paper borrows from Eom et al. for jumps
  and hops; pieces still too long are cut evenly.

Registration: per phase, the segment of median length is the reference (the paper picks "one
of the segments"; the median length needs the least warping on average). Every segment's poses
are compared in the heading frame at the root's ground point (translation on the ground plane
and rotation about the vertical removed, as in Kovar and Gleicher 2003), aligned to the
reference by dynamic time warping (:func:`dtaidistance.dtw_ndim.warping_path`), and the same
warp is applied to its full-body features and to its sensor signals: each reference frame gets
the mean of the segment frames the path matches to it. All segments of a phase then have the
reference's length, frame by frame in correspondence.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from dtaidistance import dtw_ndim
from scipy.signal import argrelextrema

from imuloco.core.motion import Motion
from imuloco.phases import GAIT8, gait_phases

NUM_PHASES = len(GAIT8)


@dataclass
class Segment:
    """One phase segment of one clip: frames ``[start, stop)`` of clip ``clip``."""

    clip: int
    phase: int
    start: int
    stop: int

    @property
    def length(self) -> int:
        return self.stop - self.start


def split_by_speed(speed: np.ndarray, max_len: int) -> list[tuple[int, int]]:
    """Cut ``range(len(speed))`` at the local minima and maxima of ``speed`` so that no piece is
    longer than ``max_len`` frames (pieces without an extremum are cut evenly).

    speed : ndarray, shape (n,), root speed over one segment.
    """
    n = len(speed)
    if n <= max_len:
        return [(0, n)]
    ext = np.union1d(argrelextrema(speed, np.less_equal)[0], argrelextrema(speed, np.greater)[0])
    cuts = [0]
    for e in ext[(ext > 0) & (ext < n)]:
        if e - cuts[-1] >= max(1, max_len // 2):
            cuts.append(int(e))
    cuts.append(n)
    out = []
    for a, b in itertools.pairwise(cuts):
        k = int(np.ceil((b - a) / max_len))
        edges = np.linspace(a, b, k + 1).round().astype(int)
        out += [(int(p), int(q)) for p, q in itertools.pairwise(edges) if q > p]
    return out


def segment_clip(motion: Motion, clip: int, max_len: int) -> tuple[list[Segment], np.ndarray]:
    """Phase segments of one clip and its foot contacts.

    Returns
    -------
    segments : whole phases only (see the module docstring), in time order.
    contacts : ndarray, shape (T, 2), left and right foot contact, float 0/1.
    """
    g = gait_phases(motion)
    contacts = np.stack([g.contacts["left_foot"], g.contacts["right_foot"]], -1).astype(float)
    labels = g.phase
    edges = np.flatnonzero(labels[1:] != labels[:-1]) + 1
    starts = np.concatenate([[0], edges])
    stops = np.concatenate([edges, [labels.size]])
    speed = np.linalg.norm(np.gradient(motion.root, axis=0), axis=-1) * motion.fps
    segs = []
    for a, b in list(zip(starts, stops))[1:-1]:
        for p, q in split_by_speed(speed[a:b], max_len):
            segs.append(Segment(clip, int(labels[a]), int(a + p), int(a + q)))
    return segs, contacts


def warp_matrix(path: Sequence[tuple[int, int]], n: int, m: int) -> np.ndarray:
    """The averaging matrix W (m, n) of a warping path between a segment of ``n`` frames and a
    reference of ``m``: ``W @ features`` gives the segment on the reference's time axis."""
    p = np.asarray(path, dtype=np.int64).reshape(-1, 2)
    w = np.zeros((m, n))
    np.add.at(w, (p[:, 1], p[:, 0]), 1.0)
    return w / w.sum(axis=1, keepdims=True)


def reference_index(lengths: np.ndarray) -> int:
    """The segment of median length (the lower median; the first such segment)."""
    lengths = np.asarray(lengths)
    target = np.sort(lengths)[(len(lengths) - 1) // 2]
    return int(np.flatnonzero(lengths == target)[0])


def register_phase(
    segments: list[Segment], reg: list[np.ndarray], x: list[np.ndarray], y: list[np.ndarray]
) -> tuple[np.ndarray, np.ndarray, int]:
    """Register all segments of one phase to its reference segment.

    Parameters
    ----------
    segments : the phase's segments.
    reg : per clip, ndarray, shape (T, R), registration features (heading-frame positions).
    x : per clip, ndarray, shape (T, dx), full-body features.
    y : per clip, ndarray, shape (T, dy), sensor features.

    Returns
    -------
    X : ndarray, shape (H, L, dx); Y : ndarray, shape (H, L, dy); the reference's index.
    """
    ref = reference_index(np.array([s.length for s in segments]))
    r = segments[ref]
    ref_feat = np.ascontiguousarray(reg[r.clip][r.start:r.stop], dtype=np.float64)
    m = r.length
    xs = np.empty((len(segments), m, x[0].shape[1]))
    ys = np.empty((len(segments), m, y[0].shape[1]))
    for k, s in enumerate(segments):
        if k == ref:
            w = np.eye(m)
        else:
            feat = np.ascontiguousarray(reg[s.clip][s.start:s.stop], dtype=np.float64)
            w = warp_matrix(dtw_ndim.warping_path(feat, ref_feat), s.length, m)
        xs[k] = w @ x[s.clip][s.start:s.stop]
        ys[k] = w @ y[s.clip][s.start:s.stop]
    return xs, ys, ref
