"""Transitions and the forward algorithm of the hierarchical HMM (Mousas 2017 sec. 5.2, 6, App. A).

The hierarchy is flattened for inference, as in Murphy and Paskin's linear-time HHMM inference
that sec. 6 cites: every frame state of every registered segment is one state of a flat chain
array, segments sorted by phase. One forward step costs O(N) in the number of frame states:

- inside a segment, a frame state moves to itself, the next frame or the one after
  (``a_frame = (self, next, skip)``, 1/3 each in the paper); moves past the last frame end the
  segment;
- the mass that ends a segment of phase ``h`` goes, at the upper level, to phase ``h`` again
  (``a_self^phase``), to the phases that follow ``h`` (``a_next^phase``, spread over the
  successors seen in training, see :class:`Topology`) or to any phase (``a_exit^phase``,
  spread evenly over the phases: the search for another behaviour); entering a phase starts
  one of its segments at its first frame, each with the same probability (pi).

The forward variable is kept scaled (Rabiner 1989 sec. V.A): it is renormalised to sum 1 at
every step and the log of the scale is accumulated, so 10^4 and more steps neither underflow
nor overflow. A missing observation (NaN sample) propagates the transitions without an update.
Hand-written because no library's HMM (hmmlearn, pomegranate) offers an online, O(N) step for
this sparse structure: their forward passes are offline and use a dense N x N matrix.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Topology:
    """Left-to-right chains of frame states grouped into phases.

    A phase ``h`` holds ``H`` segments of ``L`` frame states each (registration gives all
    segments of a phase the reference's length). Its states form one block, stored frame-major:
    frame ``j`` of segment ``s`` is state ``start + j H + s``. Frame shifts inside segments are
    then shifts of the block by ``H``, a segment's first (last) states are one contiguous run,
    and the states sharing a registered frame (one covariance group, see :mod:`.model`) too.

    Parameters
    ----------
    phases : ndarray, shape (B,), int, the phase of each block, increasing.
    counts : ndarray, shape (B,), int >= 1, segments H per block.
    lengths : ndarray, shape (B,), int >= 1, frame states L per segment.
    next_phase : ndarray, shape (P, P), row h: weights of the phases that follow h (rows of
        phases without a block are ignored; an all-zero row means the next phase in cycle
        order that has a block).
    a_frame : (self, next, skip) transition probabilities inside a segment.
    a_phase : (self, next, exit) transition probabilities between segments.
    dtype : of the forward variable.
    """

    phases: np.ndarray
    counts: np.ndarray
    lengths: np.ndarray
    next_phase: np.ndarray
    a_frame: tuple[float, float, float] = (1 / 3, 1 / 3, 1 / 3)
    a_phase: tuple[float, float, float] = (1 / 3, 1 / 3, 1 / 3)
    dtype: type = np.float64
    blocks: list[tuple[int, int, int, int]] = field(init=False)
    phase_trans: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.phases = np.asarray(self.phases, dtype=np.int64)
        self.counts = np.asarray(self.counts, dtype=np.int64)
        self.lengths = np.asarray(self.lengths, dtype=np.int64)
        p = np.asarray(self.next_phase).shape[0]
        if self.phases.size == 0 or np.any(self.counts < 1) or np.any(self.lengths < 1):
            raise ValueError("Topology: needs at least one block, each with H >= 1, L >= 1")
        if np.any(np.diff(self.phases) <= 0) or self.phases.max() >= p:
            raise ValueError(f"Topology: block phases must increase and be < {p}")
        for name, a in (("a_frame", self.a_frame), ("a_phase", self.a_phase)):
            if len(a) != 3 or min(a) < 0 or abs(sum(a) - 1) > 1e-9:
                raise ValueError(f"Topology: {name} must be 3 probabilities summing to 1, got {a}")
        present = np.zeros(p, dtype=bool)
        present[self.phases] = True
        nxt = np.where(present[None, :], np.asarray(self.next_phase, dtype=np.float64), 0.0)
        rowsum = nxt.sum(axis=1, keepdims=True)
        cyc = np.zeros((p, p))
        for h in range(p):  # fallback: the next phase in cycle order that has segments
            k = next((h + d) % p for d in range(1, p + 1) if present[(h + d) % p])
            cyc[h, k] = 1.0
        nxt = np.where(rowsum > 0, nxt / np.maximum(rowsum, 1e-300), cyc)
        s, n, e = self.a_phase
        self.phase_trans = s * np.eye(p) * present[None, :] + n * nxt + \
            e * present[None, :] / present.sum()
        sizes = self.counts * self.lengths
        starts = np.cumsum(sizes) - sizes
        self.blocks = [(int(h), int(st), int(c), int(ln)) for h, st, c, ln in
                       zip(self.phases, starts, self.counts, self.lengths)]
        last = starts + sizes - self.counts
        prev = np.where(self.lengths >= 2, last - self.counts, last)
        index = np.stack([prev, last, starts + sizes], axis=1).ravel()[:-1]
        self._run_index = index.astype(np.intp)
        self._prev_pos = np.arange(len(starts)) * 3
        self._last_pos = self._prev_pos + 1
        self._prev_w = np.where(self.lengths >= 2, self.a_frame[2], 0.0)

    @property
    def num_states(self) -> int:
        return int(np.sum(self.counts * self.lengths))

    @property
    def num_phases(self) -> int:
        return int(np.asarray(self.next_phase).shape[0])

    def initial(self) -> np.ndarray:
        """pi: every frame state equally likely (a stream may start anywhere in a stride)."""
        return np.full(self.num_states, 1.0 / self.num_states, dtype=self.dtype)

    def predict(self, alpha: np.ndarray, out: np.ndarray | None = None,
                work: np.ndarray | None = None, scaled: bool = True) -> np.ndarray:
        """One transition: ``sum_i alpha_i a_ij`` for every j, shape (N,) -> (N,).

        out, work : optional preallocated (N,) buffers of alpha's dtype (``out`` is returned);
        a stream passes them so that no large array is allocated per frame.
        scaled : False returns the prediction divided by ``a_self`` of the frame level (when it
            is > 0), a common factor that a normalised forward step removes anyway: with the
            paper's equal probabilities the shifts are then plain additions (no multiply
            passes, no temporary).
        """
        fs, fn, fk, scale = self.frame_weights(scaled)
        # mass that moves past the last frame ends the segment: the sums of every block's last
        # and second-to-last frame runs, all in one reduceat
        runs = np.add.reduceat(alpha, self._run_index)
        out_phase = np.zeros(self.num_phases)
        out_phase[self.phases] = runs[self._last_pos] * (fn + fk) + \
            runs[self._prev_pos] * (self._prev_w / scale)
        # Python floats: a NumPy float64 scalar would make each float32 add below a float64
        # loop with casts (three times slower)
        entry = (out_phase @ self.phase_trans).tolist()
        pred = np.empty_like(alpha) if out is None else out
        tmp = np.empty_like(alpha) if work is None else work

        def weighted(src: np.ndarray, w: float) -> np.ndarray:
            return src if w == 1.0 else np.multiply(src, w, out=tmp[:src.size])

        # one pass per block and move, each writing pred from alpha (no copy of alpha first):
        # pred = a_self alpha + entry (first frames) + a_next shift_H(alpha) + a_skip shift_2H
        for h, st, big_h, length in self.blocks:
            end = st + big_h * length
            self_part = alpha
            if fs != 1.0:
                self_part = pred
                np.multiply(alpha[st: end], fs, out=pred[st: end])
            first = slice(st, st + big_h)  # pi: each segment's first frame alike
            np.add(self_part[first], entry[h] / big_h, out=pred[first])
            if length >= 2:  # next frame: a shift by H inside the block
                rest = slice(st + big_h, end)
                np.add(self_part[rest], weighted(alpha[st: end - big_h], fn), out=pred[rest])
            if length >= 3 and fk != 0.0:  # skip a frame
                dst = pred[st + 2 * big_h: end]
                np.add(dst, weighted(alpha[st: end - 2 * big_h], fk), out=dst)
        return pred

    def frame_weights(self, scaled: bool = True) -> tuple[float, float, float, float]:
        """The frame level's (self, next, skip) of :meth:`predict` and the factor they were
        divided by: 1, or ``a_self`` when ``scaled`` is False and it is > 0."""
        fs, fn, fk = self.a_frame
        scale = fs if (fs > 0 and not scaled) else 1.0
        return fs / scale, fn / scale, fk / scale, scale

    def dense(self) -> np.ndarray:
        """The full transition matrix (N, N), ``A[i, j] = P(j | i)`` (for tests, small N)."""
        eye = np.eye(self.num_states, dtype=self.dtype)
        return np.stack([self.predict(row) for row in eye])


def forward_step(topology: Topology, alpha: np.ndarray, emission: np.ndarray | None
                 ) -> tuple[np.ndarray, float]:
    """One scaled forward step (App. A): predict, weight by the emission, renormalise.

    alpha : ndarray, shape (N,), the previous forward variable (sums to 1).
    emission : ndarray, shape (N,), ``b_i(y_t)`` up to a common factor, or None when the
        sample is missing (no update).

    Returns the new alpha (sums to 1) and ``log c_t``, the log of the normaliser.
    """
    pred = topology.predict(alpha)
    if emission is None:
        return pred / pred.sum(), 0.0
    a = pred * emission
    c = float(a.sum())
    if not c > 0:  # every state impossible at float precision: restart from the prediction
        return pred / pred.sum(), -np.inf
    a /= c
    return a, float(np.log(c))


def forward(topology: Topology, log_emissions: np.ndarray) -> tuple[np.ndarray, float]:
    """Offline scaled forward pass. log_emissions : (T, N) (rows of NaN: missing).

    Returns alpha (T, N), each row the filtering distribution p(state_t | y_1..t), and the total
    log-likelihood ``log p(y_1..T)``.
    """
    alpha = np.empty(log_emissions.shape)
    loglik = 0.0
    a = None
    for t, ll in enumerate(log_emissions):
        missing = bool(np.isnan(ll).any())
        m = 0.0 if missing else float(ll.max())
        b = None if missing else np.exp(ll - m)
        if a is None:
            a = topology.initial() * (1.0 if b is None else b)
            c = a.sum()
            a = a / c
            loglik += float(np.log(c)) + m
        else:
            a, logc = forward_step(topology, a, b)
            loglik += logc + m
        alpha[t] = a
    return alpha, loglik
