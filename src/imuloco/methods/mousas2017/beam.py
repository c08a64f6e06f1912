"""The forward step pruned to a beam of segments (a beam search over the lower level's chains).

The exact step (:meth:`.forward.Topology.predict` with every state's emission) touches all N
frame states every frame. Mass inside a segment only moves to later frames of the same
segment, and mass that leaves a segment enters the first frame of every segment of the phases
it goes to, each alike (pi). So the forward variable is kept on ``width`` segments only:

1. the kept segments' mass moves inside each segment (self, next, skip) as one small dense
   array ``(n, W)``, one row per segment padded to ``W = max L + 2`` frames: the mass that
   moves into the padding is the mass that ends the segment, which goes up to the phase level
   and comes back as the entry of each phase (``pi``), as in the exact step;
2. emissions are computed for the kept segments' frames and for the first frame of every
   segment (one contiguous matrix-vector product), not for the other states;
3. a segment outside the beam holds only its entry mass times its first frame's emission; it
   joins when that reaches the ``width``-th largest segment mass of the continuing ones (which
   bounds the new beam's threshold from below, so no segment that belongs in the beam is
   missed);
4. the ``width`` segments of largest mass are kept and the forward variable is renormalised
   over them (float64).

The upper level's emission (eq. 8, the mean over a phase's segments at one registered frame)
counts the frames outside the beam at the emission floor. With ``width`` >= the number of
segments nothing is pruned and the step is the exact one (in float64, to rounding).

The successors of a segment's frames are a fixed slice of its padded row, so one gather of
rows replaces a sparse (CSR) successor table and the de-duplication of successor sets: no
per-state Python work, and no per-frame array of N states. Hand-written for the reason
:mod:`.forward` gives (no library offers an online step for this structure).

The segments kept are chosen by :func:`keep_largest` (ties to the lower index), so that the
numpy step and the compiled one (:func:`.compiled.beam_step`, engine numba) keep the same.
Measured on the shared data (docs/results/mousas2017/speed.md): a quarter of the mass sits on
first frames every frame, so thousands of segments pass the entry test each step (6,000 to
15,000 of 21,536 at 100k database frames), each needing its emission, and every first frame
is scanned each step; no width was both clearly faster than the exact step and as accurate,
also compiled, so the method's default is the exact step. The scan is not replaced by an
index: within a block the entry test is a ball in the first group's whitened space, but a
k-d tree per block (scipy, scikit-learn) returns thousands of segments a step and its queries
cost more than the whole exact step (``benchmarks/mousas_beam_index.py``).
"""

from __future__ import annotations

import numpy as np

from imuloco.methods.mousas2017.forward import Topology
from imuloco.methods.mousas2017.model import FrameStates

# Segment masses within this relative distance of the K-th largest are ties, decided by the
# segment's index: the numpy and the compiled step then pick the same K segments although
# their sums round differently (a flat forward variable, as after missing samples, has many
# segments of the same mass up to float32 rounding). Used by the interpolation's K segments
# (:func:`.stream.top_segments`) and the beam's ``width``.
TIE_RTOL = 1e-5


def keep_largest(v: np.ndarray, k: int) -> np.ndarray:
    """Mask (n,) of the k largest entries of v (n,), 0 < k <= n: those above the k-th largest
    by more than :data:`TIE_RTOL` (relative), then the lowest indices among the ties."""
    thr = float(np.partition(v, v.size - k)[v.size - k])
    keep = v > thr * (1.0 + TIE_RTOL)
    tie = ~keep & (v >= thr * (1.0 - TIE_RTOL))
    return keep | (tie & (np.cumsum(tie) <= k - int(keep.sum())))


class SegmentBeam:
    """Pruned forward variable of the lower level over ``width`` segments.

    Segments are numbered block by block (segment ``s`` of block ``b`` is ``seg0[b] + s``);
    frame ``j`` of that segment is state ``start_b + j H_b + s`` (:class:`.forward.Topology`).

    After :meth:`step`: ``seg`` (n,) the kept segments, ``alpha`` (n, W) their frames'
    forward probabilities (zero in the padding; all n W sum to 1 up to the floor), ``mass``
    (n,) the row sums.
    """

    def __init__(self, lower: Topology, fs: FrameStates, width: int,
                 emission_floor: float, alpha_floor: float) -> None:
        if width < 1:
            raise ValueError(f"SegmentBeam: width must be >= 1, got {width}")
        self.width = int(width)
        self.lower = lower
        self.emission_floor = emission_floor
        self.alpha_floor = alpha_floor
        counts, lengths = lower.counts, lower.lengths
        num_groups = fs.group_count.size
        self.W = int(lengths.max()) + 2
        starts = np.cumsum(counts * lengths) - counts * lengths
        self.seg0 = np.cumsum(counts) - counts                      # (B,) first segment id
        self.num_segments = int(counts.sum())
        self.block = np.repeat(np.arange(counts.size), counts)       # (S,) block of a segment
        s_in = np.arange(self.num_segments) - self.seg0[self.block]  # (S,) s inside the block
        j = np.arange(self.W)
        length = lengths[self.block][:, None]
        self.valid = j[None, :] < length                             # (S, W)
        self.pad = ~self.valid
        n = lower.num_states
        # state of every (segment, frame); the padding points at a dummy state n
        self.states = np.where(self.valid, (starts[self.block] + s_in)[:, None]
                               + j[None, :] * counts[self.block][:, None], n)
        dummy_g = num_groups  # the padding's group: quad = inf there, so log b = -inf
        g0 = np.searchsorted(fs.group_phase, lower.phases)  # (B,) first group of each block
        self.group = np.where(self.valid, g0[self.block][:, None] + j[None, :], dummy_g)
        lin = np.zeros((n + 1, fs.lin.shape[0] + 1), dtype=np.float32)
        lin[:n, :-1] = fs.lin.T
        lin[:n, -1] = fs.const
        self.lin = lin[self.states]                                  # (S, W, dy + 1)
        self.first_lin = np.ascontiguousarray(self.lin[:, 0].T)      # (dy + 1, S)
        self.first_group = self.group[:, 0]
        self.fs = fs
        self.counts = counts
        self.group_count = fs.group_count.astype(np.float64)
        self._phase = lower.phases[self.block]                       # (S,)
        self._quad = np.empty(num_groups + 1, dtype=fs.lin.dtype)
        self._quad[-1] = np.inf
        self._y = np.ones(fs.lin.shape[0] + 1, dtype=fs.lin.dtype)  # the sample and 1
        self.seg: np.ndarray | None = None
        self._kernel_args: tuple | None = None  # of step_compiled, after the first step
        self.alpha = np.zeros((0, self.W))
        self.mass = np.zeros(0)

    # ---- one step -----------------------------------------------------------------------------
    def step(self, y: np.ndarray | None) -> np.ndarray | None:
        """One forward step with sensor frame ``y`` (dy,), or None when missing. Returns the
        upper level's emission (G,) of eq. 8 (None when missing)."""
        if self.seg is None:  # pi: every frame state alike, every segment a candidate
            seg = np.arange(self.num_segments)
            pred = self.valid / float(self.lower.num_states)
            entry = np.zeros(self.counts.size)
        else:
            seg, pred, entry = self._predict()
        if y is None:
            a, b, raw, limit = pred, None, None, np.zeros(self.counts.size)
        else:
            self._y[:-1] = y
            quad = self._quad
            quad[:-1] = self.fs.quad(y)
            ll = self.lin[seg] @ self._y - quad[self.group[seg]]               # (n, W)
            # first frames: log b_i + quad of the block's first group (shared by the block)
            raw = self._y @ self.first_lin                                    # (S,)
            q0 = quad[self.first_group[self.seg0]]                            # (B,)
            top = max(float(ll.max()), float((np.maximum.reduceat(raw, self.seg0) - q0).max()))
            b = np.exp(ll - top)
            b += self.emission_floor
            a = pred * b
            limit = q0 + top
        mass = a.sum(1)
        new, new_b = self._entrants(seg, mass, entry, raw, limit)
        bu = None if y is None else self._upper_emission(seg, b, new, new_b)
        self._prune(seg, a, mass, new, entry[self.block[new]] * new_b)
        return bu

    def _predict(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The kept segments' mass moved one frame (n, W) and each block's entry mass per
        first frame (B,)."""
        fs_, fn, fk = self.lower.a_frame
        a = self.alpha
        pred = a * fs_
        pred[:, 1:] += fn * a[:, :-1]
        pred[:, 2:] += fk * a[:, :-2]
        seg = self.seg
        ended = (pred * self.pad[seg]).sum(1)  # the mass moved into the padding ends
        pred *= self.valid[seg]
        out_phase = np.bincount(self._phase[seg], ended, minlength=self.lower.num_phases)
        entry = (out_phase @ self.lower.phase_trans)[self.lower.phases] / self.counts
        pred[:, 0] += entry[self.block[seg]]
        return seg, pred, entry

    def _entrants(self, seg: np.ndarray, mass: np.ndarray, entry: np.ndarray,
                  raw: np.ndarray | None, offset: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Segments outside ``seg`` whose entry mass times first frame's emission reaches the
        ``width``-th largest of ``mass`` (n,), and that emission (relative to the kept
        frames' common factor, floor included; 1 when the sample is missing). raw : (S,)
        first frames' ``log b_i + offset`` of their block (None: missing); offset : (B,)."""
        floor = self.emission_floor if raw is not None else 0.0
        k = mass.size - self.width
        thr = float(np.partition(mass, k)[k]) if k >= 0 else 0.0
        with np.errstate(divide="ignore", invalid="ignore"):
            # per block: e b_i >= thr, i.e. log b_i - offset >= log(thr / e - floor)
            need = thr / entry - floor
            lim = np.where(need > 0, np.log(need), -np.inf)
        lim = np.where(entry > 0, lim + offset, np.inf)
        if raw is None:
            ok = np.repeat(lim <= 0.0, self.counts)
        else:
            ok = raw >= np.repeat(lim, self.counts)
        ok[seg] = False
        new = np.flatnonzero(ok)
        if raw is None:
            return new, np.ones(new.size)
        return new, np.exp(raw[new] - offset[self.block[new]]) + floor

    def _upper_emission(self, seg: np.ndarray, b: np.ndarray, new: np.ndarray,
                        new_b: np.ndarray) -> np.ndarray:
        """Eq. 8's mean over each group's segments: the computed frames' emissions, the others'
        at the floor."""
        g = self.group_count.size
        grp = self.group[seg].ravel()
        num = np.bincount(grp, b.ravel(), minlength=g + 1)[:g]
        cnt = np.bincount(grp, minlength=g + 1)[:g].astype(np.float64)
        if new.size:
            fg = self.first_group[new]
            num += np.bincount(fg, new_b, minlength=g)
            cnt += np.bincount(fg, minlength=g)
        return (num + (self.group_count - cnt) * self.emission_floor) / self.group_count

    def _prune(self, seg: np.ndarray, a: np.ndarray, mass: np.ndarray, new: np.ndarray,
               new_a: np.ndarray) -> None:
        """Keep the ``width`` segments of largest mass among the continuing (rows of ``a``)
        and the entering (``new_a`` on their first frame), renormalised."""
        n = seg.size
        if n + new.size > self.width:
            keep = np.flatnonzero(keep_largest(np.concatenate([mass, new_a]), self.width))
            cont, ent = keep[keep < n], keep[keep >= n] - n
            seg, a, mass = seg[cont], a[cont], mass[cont]
            new, new_a = new[ent], new_a[ent]
        if new.size:
            rows = np.zeros((new.size, self.W))
            rows[:, 0] = new_a
            seg, a = np.concatenate([seg, new]), np.concatenate([a, rows])
            mass = np.concatenate([mass, new_a])
        c = mass.sum()
        if not c > 0:  # every kept state impossible at float precision: spread evenly
            a = self.valid[seg].astype(np.float64)
            c = a.sum()
            mass = a.sum(1)
        a /= c
        mass /= c
        a += self.alpha_floor * self.valid[seg]
        self.seg, self.alpha, self.mass = seg, a, mass

    # ---- the compiled step ------------------------------------------------------------------
    def step_compiled(self, kernels, y: np.ndarray | None, bu: np.ndarray) -> None:
        """:meth:`step` after the first, by :func:`.compiled.beam_step` (the same arithmetic,
        to float rounding): sets ``bu`` (G,) to eq. 8's emission when ``y`` (dy,) is given."""
        if self._kernel_args is None:
            member = np.zeros(self.num_segments, dtype=bool)
            member[self.seg] = True
            self._kernel_args = (
                np.ascontiguousarray(self.fs.prec, dtype=np.float64), self._quad, self.lin,
                self.first_lin, self.group, np.ascontiguousarray(self.first_group), self.seg0,
                self.block, self.lower.lengths[self.block].astype(np.int64),
                self.lower.phases.astype(np.int64), self.counts.astype(np.int64),
                np.ascontiguousarray(self.lower.phase_trans, dtype=np.float64),
                np.array(self.lower.a_frame, dtype=np.float64), self.group_count, self.width,
                self.emission_floor, self.alpha_floor, TIE_RTOL, member, bu)
        if y is not None:
            self._y[:-1] = y
        self.seg, self.alpha, self.mass = kernels.beam_step(
            self.seg, self.alpha, y is not None, self._y, *self._kernel_args[:-1], bu)

    # ---- views --------------------------------------------------------------------------------
    def dense(self) -> np.ndarray:
        """The forward variable over all N states (N,), zero outside the beam."""
        out = np.zeros(self.lower.num_states + 1)
        out[self.states[self.seg]] = self.alpha
        return out[:-1]

    def block_segments(self, b: int) -> tuple[np.ndarray, np.ndarray]:
        """The kept segments of block ``b`` (their ``s`` inside the block) and their frames'
        forward probabilities (m, L_b)."""
        rows = np.flatnonzero(self.block[self.seg] == b)
        rows = rows[np.argsort(self.seg[rows])]  # by index, so that ties go to the lower one
        return self.seg[rows] - self.seg0[b], self.alpha[rows, :int(self.lower.lengths[b])]
