"""Phase segmentation of sensor signals with discrete HMMs, Eom et al. 2014 sec. 5.4 and 6.1.

- :func:`fit_levels` / :func:`discretize`: the slope of each (smoothed) sensor dimension at
  every frame, coded as one of ``levels`` integers on uniform intervals (Fig. 5). The paper does
  not say which range the intervals span; here it is ``[-r, r]`` with ``r`` the 95th percentile
  of the training slopes' magnitude per dimension (slopes beyond fall in the end bins), so that
  with 3 levels the codes read "falling / flat / rising".
- :func:`fit_phase_hmms`: one discrete HMM per phase, trained on that phase's blocks ``c_i``
  (Fig. 6) with hmmlearn's CategoricalHMM. The paper applies the HMM "to each dimension of
  the sensor data" (sec. 6.1): each phase has one HMM per sensor dimension and a window's
  likelihood is the product over dimensions (mlpack's discrete HMM of 2014 took one symbol per
  step). The number of hidden states is not given; 4 by default.
- :func:`window_loglik`, :func:`majority_vote`: the phase of every window of ``v`` frames is
  the HMM with the highest P(O|U); each frame takes the phase most windows covering it chose
  (Fig. 7). :func:`causal_phase` is the online variant: the window ending at the frame only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from hmmlearn.hmm import CategoricalHMM
from scipy.special import logsumexp


def slopes(signals: np.ndarray) -> np.ndarray:
    """Backward differences along time (first row repeats the second). (T, k) -> (T, k)."""
    d = np.diff(signals, axis=0)
    return np.concatenate([d[:1], d], axis=0) if len(d) else np.zeros_like(signals)


def fit_levels(signals: list[np.ndarray], levels: int = 3, percentile: float = 95.0
               ) -> np.ndarray:
    """Inner bin edges of the slope coding, shape (levels - 1, k), from training signals
    (a list of (T, k) smoothed sensor sequences)."""
    s = np.abs(np.concatenate([slopes(x) for x in signals]))
    r = np.maximum(np.percentile(s, percentile, axis=0), 1e-12)
    return np.linspace(-1.0, 1.0, levels + 1)[1:-1, None] * r[None, :]


def discretize(signals: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Slope codes (T, k) int in ``[0, levels)`` of signals (T, k), edges (levels - 1, k)."""
    s = slopes(np.asarray(signals, dtype=np.float64))
    return (s[:, None, :] > edges[None]).sum(1).astype(np.int64)


@dataclass
class PhaseHMMs:
    """Discrete HMMs, one per (phase, sensor dimension).

    startprob : ndarray, shape (P, k, n); transmat : (P, k, n, n); emission : (P, k, n, L),
    for P phases, k sensor dimensions, n hidden states and L levels.
    """

    startprob: np.ndarray
    transmat: np.ndarray
    emission: np.ndarray

    @property
    def num_phases(self) -> int:
        return self.startprob.shape[0]


def fit_phase_hmms(blocks: list[list[np.ndarray]], levels: int = 3, n_states: int = 4,
                   n_iter: int = 15, seed: int = 0, max_frames: int = 4000) -> PhaseHMMs:
    """One CategoricalHMM per phase and sensor dimension (Baum-Welch, hmmlearn).

    blocks : per phase, the list of its code sequences, each (T_b, k) int (the blocks of
        Fig. 6: contiguous runs of frames labelled with that phase).
    max_frames : per phase, blocks beyond this many frames in all are left out (spread evenly
        over the list), bounding the training time.
    """
    rng = np.random.default_rng(seed)
    k = blocks[0][0].shape[1]
    start = np.zeros((len(blocks), k, n_states))
    trans = np.zeros((len(blocks), k, n_states, n_states))
    emis = np.zeros((len(blocks), k, n_states, levels))
    for p, bl in enumerate(blocks):
        order = rng.permutation(len(bl))
        keep, total = [], 0
        for i in order:
            if total >= max_frames:
                break
            keep.append(bl[i])
            total += len(bl[i])
        seq = np.concatenate(keep)
        lengths = [len(b) for b in keep]
        for d in range(k):
            hmm = CategoricalHMM(n_components=n_states, n_features=levels, n_iter=n_iter,
                                 random_state=int(rng.integers(2**31)), init_params="ste",
                                 implementation="scaling")
            hmm.fit(seq[:, d:d + 1], lengths)
            start[p, d], trans[p, d] = hmm.startprob_, hmm.transmat_
            emis[p, d] = hmm.emissionprob_
    # floor the probabilities so that a symbol unseen in training does not give -inf
    emis = (emis + 1e-3) / (emis + 1e-3).sum(-1, keepdims=True)
    trans = (trans + 1e-6) / (trans + 1e-6).sum(-1, keepdims=True)
    start = (start + 1e-6) / (start + 1e-6).sum(-1, keepdims=True)
    return PhaseHMMs(start, trans, emis)


def window_loglik(codes: np.ndarray, hmms: PhaseHMMs, window: int) -> np.ndarray:
    """ln P(O | U) of every window of ``window`` frames under every phase's HMMs.

    The forward algorithm is written out here (scaled, in numpy) because hmmlearn scores one
    sequence per call and there are T windows times P k HMMs per clip.

    codes : ndarray, shape (T, k), int slope codes.
    Returns ndarray, shape (T - v + 1, P) with ``v = min(window, T)``; entry ``[s, p]`` is the
    window of frames ``s .. s + v - 1`` under phase p (summed over the k dimensions).
    """
    codes = np.asarray(codes, dtype=np.int64)
    t = codes.shape[0]
    v = min(window, t)
    nw = t - v + 1
    # emission probability of every frame's symbol: (P, k, T, n)
    e = np.take_along_axis(hmms.emission.transpose(0, 1, 3, 2)[:, :, None],  # (P,k,1,L,n)
                           codes.T[None, :, :, None, None], axis=3)[:, :, :, 0, :]
    a = hmms.startprob[:, :, None, :] * e[:, :, 0:nw]          # (P, k, W, n)
    c = a.sum(-1, keepdims=True)
    ll = np.log(c[..., 0])
    a = a / c
    for i in range(1, v):
        a = np.einsum("pkwn,pknm->pkwm", a, hmms.transmat) * e[:, :, i:i + nw]
        c = a.sum(-1, keepdims=True)
        ll += np.log(c[..., 0])
        a = a / c
    return ll.sum(1).T                                          # (W, P)


def majority_vote(window_phase: np.ndarray, num_frames: int, window: int, num_phases: int
                  ) -> np.ndarray:
    """Per-frame phase by majority vote of the windows covering the frame (Fig. 7).

    window_phase : ndarray, shape (W,), int: the phase chosen for the window starting at each
        frame, ``W = T - v + 1``. Returns ndarray, shape (T,), int (ties: the lower index).
    """
    v = num_frames - len(window_phase) + 1
    onehot = np.zeros((len(window_phase) + 1, num_phases))
    onehot[1 + np.arange(len(window_phase)), window_phase] = 1.0
    cum = np.cumsum(onehot, axis=0)
    i = np.arange(num_frames)
    hi = np.minimum(i, len(window_phase) - 1) + 1
    lo = np.maximum(i - v + 1, 0)
    return np.argmax(cum[hi] - cum[lo], axis=1)


def segment_phases(codes: np.ndarray, hmms: PhaseHMMs, window: int) -> np.ndarray:
    """Per-frame phase (T,) of a whole sequence of codes (T, k): sec. 6.1."""
    ll = window_loglik(codes, hmms, window)
    return majority_vote(np.argmax(ll, axis=1), len(codes), window, hmms.num_phases)


def sequence_score(codes: np.ndarray, hmms: PhaseHMMs, window: int) -> float:
    """Mean over windows of ln sum_p P(O | U, phase p) / P: how well a set of phase HMMs
    explains a sequence (used to pick the motion type's model)."""
    ll = window_loglik(codes, hmms, window)
    return float(np.mean(logsumexp(ll, axis=1) - np.log(ll.shape[1])))
