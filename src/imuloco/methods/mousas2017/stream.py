"""Online reconstruction, one sensor frame at a time (Mousas 2017 sec. 5.3 and 6).

Each step:

1. emissions ``b_i(y_t)`` of all frame states (one matrix-vector product, :mod:`.model`);
2. the forward step of both levels (:mod:`.forward`; the lower level's optionally pruned to
   a beam of segments, :mod:`.beam`, which then also gives eq. 8's emission): the upper
   level (one chain per phase over its registered frames, emission eq. 8) gives
   ``p(S_h | y_1..t)`` and the most probable phase; the lower level (one chain per segment,
   emission eq. 9) gives ``a_t(i, S_h)``;
3. reactive interpolation: the K most probable segments of that phase, by their summed forward
   probability, with weights ``a_k`` that sum to 1 (eq. 10-12), and inside each segment its
   frame states weighted by their forward probability. The pose is eq. 13: the forward-weighted
   sum of the conditional means ``mu^X(y_t)`` (eq. 6), which is the arg max of the conditional
   Gaussian. The interpolated observation ``y_bar`` (eq. 10) and covariance (eq. 12) are kept
   on the stream (``y_bar``, ``variance``);
4. velocity-based blending (after Levine et al. 2009, which the paper cites without details):
   the previous output pose is advanced by the interpolated joint angular velocities and then
   pulled towards the interpolated pose with weight ``blend`` per frame, so that a switch of
   segments or phases does not jump;
5. decoding of the root (heading integrated from the yaw rate, position from the heading-frame
   velocity, as :func:`imuloco.methods.pose.decode`) and, when enabled, the foot-skate
   clean-up of :func:`imuloco.methods.postprocess.pin_feet`, here step by step
   (:class:`~imuloco.methods.postprocess.FootPinner`), on the predicted contacts.

Steps 1-5 run as numpy calls or, with ``engine`` numba (the default when numba is
installed), as the compiled kernels of :mod:`.compiled`: the same arithmetic, about 6 times
faster at 500 database frames and 2 times at 100k (docs/results/mousas2017/speed.md).

A missing sample (any NaN) skips the emission at both levels: the transitions alone move the
forward variables (the frame "skip" and phase "exit" transitions of sec. 5.2 are what let it
recover when samples return) and the pose is the interpolated means without the regression.
"""

from __future__ import annotations

import functools
import importlib
import importlib.util
import itertools
import logging
import math
from pathlib import Path

import numpy as np

from imuloco.errors import MissingExtraError
from imuloco.methods.base import Stream
from imuloco.methods.mousas2017.beam import TIE_RTOL, SegmentBeam
from imuloco.methods.postprocess import FootPinner

log = logging.getLogger(__name__)

# These helpers run once per frame on a few dozen joints, where numpy's cost per call
# dominates: sums over a last axis of 3 are products with ones (a reduction over a short last
# axis costs several times a small matrix product), index lists are prebuilt arrays.
_ONES3 = np.ones(3)
_CROSS = (np.array([1, 2, 0, 2, 0, 1]), np.array([2, 0, 1, 1, 2, 0]))


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b for (..., 3) arrays; inline because np.cross is slow on small arrays (both
    products of the formula in one multiply of 6 components). On a pose's (21, 3): 4.6 us,
    :func:`imuloco.ops.rotations.cross` 9.4 us, np.cross 21 us (numpy 2.0); on a clip's
    (600, 21, 3) rotations.cross is 7 times faster (the gather copies)."""
    p = a[..., _CROSS[0]] * b[..., _CROSS[1]]
    return p[..., :3] - p[..., 3:]


def matrix_from_6d(d: np.ndarray) -> np.ndarray:
    """6-D rotations (..., 6) -> matrices (..., 3, 3), the Gram-Schmidt of
    :func:`imuloco.ops.rotations.from_6d` (its columns are the 6-D vector's two halves)."""
    a = d[..., :3] / np.sqrt(np.square(d[..., :3]) @ _ONES3)[..., None]
    b = d[..., 3:] - ((a * d[..., 3:]) @ _ONES3)[..., None] * a
    b /= np.sqrt(np.square(b) @ _ONES3)[..., None]
    out = np.empty(d.shape[:-1] + (3, 3))
    out[..., 0], out[..., 1], out[..., 2] = a, b, _cross(a, b)
    return out


def matrix_exp(r: np.ndarray) -> np.ndarray:
    """Rotation vectors (..., 3) -> matrices (..., 3, 3) (Rodrigues,
    ``I + sin(a)/a K + 2 (sin(a/2)/a)^2 K^2``: no cancellation for small angles a)."""
    a = np.sqrt(np.square(r) @ _ONES3)[..., None, None] + 1e-300
    k = (r @ _SKEW_MAP).reshape(r.shape[:-1] + (3, 3))
    h = np.sin(0.5 * a) / a
    return _EYE3 + (np.sin(a) / a) * k + (2.0 * h * h) * (k @ k)


_SKEW_MAP = np.zeros((3, 9))  # [r]_x as a linear map of r, flattened row-major
_SKEW_MAP[2, 1], _SKEW_MAP[1, 2], _SKEW_MAP[0, 5] = -1.0, 1.0, -1.0
_SKEW_MAP[2, 3], _SKEW_MAP[1, 6], _SKEW_MAP[0, 7] = 1.0, -1.0, 1.0
_EYE3 = np.eye(3)


def _shepperd_map() -> tuple[np.ndarray, np.ndarray]:
    """The linear map from a rotation matrix's 9 entries to the symmetric 4x4 matrix K whose
    row k is ``4 q_k q`` (quaternion x, y, z, w): ``K = m.reshape(9) @ C + c``."""
    c = np.zeros((9, 4, 4))
    e = {(i, j): 3 * i + j for i in range(3) for j in range(3)}
    diag = [(0, (1, -1, -1)), (1, (-1, 1, -1)), (2, (-1, -1, 1)), (3, (1, 1, 1))]
    for k, signs in diag:
        for i, sgn in enumerate(signs):
            c[e[i, i], k, k] = sgn
    pairs = {(0, 1): ((0, 1), (1, 0), 1), (0, 2): ((0, 2), (2, 0), 1),
             (1, 2): ((1, 2), (2, 1), 1), (0, 3): ((2, 1), (1, 2), -1),
             (1, 3): ((0, 2), (2, 0), -1), (2, 3): ((1, 0), (0, 1), -1)}
    for (a, b), (p, q, sgn) in pairs.items():
        for r, cc in ((a, b), (b, a)):
            c[e[p], r, cc] += 1
            c[e[q], r, cc] += sgn
    return c.reshape(9, 16), np.eye(4).reshape(16)


_SHEPPERD = _shepperd_map()
_ONES4 = np.ones(4)


def matrix_to_quat(m: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) -> quaternions (..., 4) x, y, z, w (Shepperd's method:
    the row of K with the largest diagonal entry, computed in one matrix product)."""
    lead = m.shape[:-2]
    k = (m.reshape(-1, 9) @ _SHEPPERD[0] + _SHEPPERD[1]).reshape(-1, 4, 4)
    best = np.argmax(k.reshape(-1, 16)[:, ::5], axis=1)
    q = k[np.arange(len(k)), best]
    q /= np.sqrt(np.square(q) @ _ONES4)[..., None]
    return q.reshape(lead + (4,))


# Floors that keep every float32 in the forward pass a normal number. Subnormal floats
# (below 1.2e-38) are 10-30 times slower in every arithmetic operation, and without floors the
# forward variable of unlikely states decays into them within a few frames. Every emission
# gets e^-40 times the best state's added (a sample that fits no state cannot rule a state out
# alone, a robust likelihood), and every state 1e-18 of forward mass after normalising (at 10^5
# states, 1e-13 in all): products then stay above 1e-36. Floors are added, not taken as
# maxima: np.maximum is about six times slower than np.add on float32.
EMISSION_FLOOR = float(np.exp(-40.0))
ALPHA_FLOOR = 1e-18
EXP_CLAMP = -60.0  # log emissions below max - 60 are clamped before exp (see _filter_exact)
ENGINES = ("auto", "numba", "numpy")


def resolve_engine(engine: str) -> str:
    """``auto`` -> ``numba`` when numba is installed, else ``numpy``; checks the name."""
    if engine not in ENGINES:
        raise ValueError(f"mousas2017: engine must be one of {', '.join(ENGINES)}, "
                         f"got {engine!r}")
    if engine == "auto":
        return "numba" if importlib.util.find_spec("numba") is not None else "numpy"
    return engine


def compiled_kernels():
    """The module of compiled kernels (:mod:`.compiled`); MissingExtraError without numba."""
    try:
        compiled = importlib.import_module("imuloco.methods.mousas2017.compiled")
    except ImportError as e:
        if e.name is None or not e.name.startswith(("numba", "llvmlite")):
            raise
        raise MissingExtraError("mousas2017's compiled step (engine=numba)", "numba",
                                "fast") from None
    _say_if_compiling(compiled)
    return compiled


@functools.cache
def _say_if_compiling(compiled) -> None:
    """Log a warning, once a process, when numba has no cached kernels yet: the first step
    then compiles them (about 25 s of CPU, once a machine), which would look like a hang."""
    try:
        folder = Path(compiled.emission._cache.cache_path)  # numba's cache of this module
    except AttributeError:  # another numba's internals: say nothing rather than guess
        return
    if not any(folder.glob(f"{Path(compiled.__file__).stem}.*.nbi")):
        log.warning("mousas2017: compiling its online step with numba (once on this machine, "
                    "about 25 s of CPU; later runs load it from %s)", folder)


def top_segments(w: np.ndarray, k: int) -> np.ndarray:
    """Indices of the k largest of w (m,), k < m: those above the k-th largest by more than
    :data:`TIE_RTOL`, then the lowest indices among the ties."""
    thr = float(np.partition(w, w.size - k)[w.size - k])
    near = np.flatnonzero(w >= thr * (1.0 - TIE_RTOL))
    if near.size == k:
        return near
    above = w > thr * (1.0 + TIE_RTOL)
    return np.concatenate([np.flatnonzero(above), np.flatnonzero(
        ~above & (w >= thr * (1.0 - TIE_RTOL)))[:k - int(above.sum())]])


class MousasStream(Stream):
    """One online session of a fitted :class:`Mousas2017` (see the module docstring).

    pin : apply the foot-skate clean-up step by step.
    beam : segments the lower level's forward variable keeps (:mod:`.beam`); 0 is the exact
        forward step over every frame state (None: the model's ``beam``).
    engine : ``numba``: the exact step's compiled kernels (:mod:`.compiled`, the ``fast``
        extra: MissingExtraError without it), ``numpy``: numpy calls, ``auto``: numba when
        installed (None: the model's ``engine``). Both compute the same step (to float
        rounding), also with a beam (:func:`.compiled.beam_step`).
    """

    def __init__(self, model, pin: bool = True, beam: int | None = None,
                 engine: str | None = None) -> None:
        self.m = model
        self.pin = pin
        self.beam = int(getattr(model, "beam", 0) if beam is None else beam)
        self.engine = resolve_engine(getattr(model, "engine", "auto") if engine is None
                                     else engine)
        self.lower = model.lower_
        self.upper = model.upper_
        self.fs = model.states_
        sk = model.skeleton_
        self.j = sk.num_joints
        self.lay = model.layout_
        self.alpha: np.ndarray | None = None
        self._beam = SegmentBeam(self.lower, self.fs, self.beam, EMISSION_FLOOR,
                                 ALPHA_FLOOR) if self.beam > 0 else None
        n = 0 if self._beam is not None else self.lower.num_states
        dtype = self.lower.dtype  # float32 in a fitted model
        self._b = np.empty(n, dtype=dtype)
        self._work = np.empty(n, dtype=dtype)
        self._pred = np.empty(n, dtype=dtype)
        # EXP_CLAMP's bits in that dtype, an unsigned integer of its size (see _filter_exact)
        self._clamp_bits = np.asarray(EXP_CLAMP, dtype=dtype).view(f"u{np.dtype(dtype).itemsize}")
        self._group_start = np.cumsum(self.fs.group_count) - self.fs.group_count
        # (phase, first group, first state, H, L) of each block
        self._blocks = [(h, g0, st, big_h, length) for (h, *_), (g0, st, big_h, length)
                        in zip(self.lower.blocks, self.fs.blocks)]
        self._a_up = self.upper.dense()
        # per block: the regression of its groups as one matrix (dx, L dy), and the offsets
        # of frame j (j H) inside the block
        reg_t = self.fs.reg.transpose(1, 0, 2)
        self._reg_blocks = [np.ascontiguousarray(reg_t[:, g0: g0 + length].reshape(
            reg_t.shape[0], -1)) for _, g0, _, _, length in self._blocks]
        self._frame_offsets = [np.arange(length)[None, :] * big_h
                               for _, _, _, big_h, length in self._blocks]
        self._phase_block = {b[0]: i for i, b in enumerate(self._blocks)}
        self.alpha_up: np.ndarray | None = None
        self.t = 0
        self.q_prev: np.ndarray | None = None
        self.r_prev: np.ndarray | None = None
        self.theta = 0.0
        self.root_raw = np.zeros(3)
        self.pinner = FootPinner()
        # diagnostics of the last step
        self.phase = -1
        self.phase_posterior = np.zeros(self.upper.num_phases)
        self.y_bar = np.zeros(self.fs.mu_y.shape[1])
        self.variance = np.zeros(self.fs.mu_x.shape[1])
        self.contacts = np.zeros(2)
        self.pose_vector = np.zeros(self.lay["pose"].stop)
        # the legs' sub-skeleton for the clean-up: joints from the root to each ankle
        feet = [sk.part("left_ankle"), sk.part("right_ankle")]
        chain: set[int] = set()
        for f in feet:
            while f >= 0:
                chain.add(int(f))
                f = int(sk.parents[f])
        self._legs = np.array(sorted(chain))
        where = {int(j): i for i, j in enumerate(self._legs)}
        self._leg_parents = np.array([where.get(int(sk.parents[j]), -1) for j in self._legs])
        self._leg_offsets = sk.offsets[self._legs]
        self._leg_feet = np.array([where[f] for f in feet])
        depth = np.zeros(self._legs.size, dtype=int)
        for i in range(1, self._legs.size):
            depth[i] = depth[self._leg_parents[i]] + 1
        self._levels = [(np.flatnonzero(depth == d), self._leg_parents[depth == d])
                        for d in range(1, depth.max() + 1)]
        chains = []
        for f in feet:  # joints below the root down to each ankle
            path = []
            while f > 0:
                path.append(int(f))
                f = int(sk.parents[f])
            chains.append(path[::-1])
        same = len(chains[0]) == len(chains[1]) and sk.parents[chains[0][0]] == 0 == \
            sk.parents[chains[1][0]]
        self._chains = np.array(chains) if same else None
        self._chain_offsets = sk.offsets[self._chains][..., None] if same else None
        self._k = compiled_kernels() if self.engine == "numba" else None
        if self._k is not None:
            self._compiled_init()

    # ---- inference --------------------------------------------------------------------------
    def _filter(self, y: np.ndarray | None) -> None:
        """Both levels' forward step: the lower level's exact or in a beam, then the upper
        level's (small: a dense product)."""
        bu = self._beam.step(y) if self._beam is not None else self._filter_exact(y)
        if self.alpha_up is None:
            self.alpha_up = self.upper.initial() if bu is None else self._norm(
                self.upper.initial() * bu)
            return
        up = self.alpha_up @ self._a_up
        if bu is not None:
            up *= bu
        c = up.sum()
        self.alpha_up = up / c if c > 0 else self._norm(self.alpha_up @ self._a_up)

    def _filter_exact(self, y: np.ndarray | None) -> np.ndarray | None:
        """The lower level's exact forward step, in preallocated float32 buffers (no per-frame
        allocation of (N,) arrays: at 10^5 states that costs more than the arithmetic);
        returns the upper level's emission (eq. 8), None when the sample is missing."""
        fs, low = self.fs, self.lower
        if y is None:
            b = bu = None
        else:
            b = fs.log_emission(y, out=self._b)
            b -= b.max()
            if b.min() < EXP_CLAMP:
                # exp is 4-5 times slower where its result underflows (a subnormal float32),
                # as it does for half the states of a frame far from most. Clamping there
                # changes nothing: e^-60 is below half an ulp of the floor added next, so the
                # sum rounds to the floor either way. b <= 0 now, and for such floats
                # max(b, c) is min on their bits as uint32 (+0 is 0, negatives grow with
                # their magnitude), which is cheaper than np.maximum's NaN-aware float loop.
                bits = b.view(self._clamp_bits.dtype)
                np.minimum(bits, self._clamp_bits, out=bits)
            np.exp(b, out=b)
            b += EMISSION_FLOOR
            # eq. 8: the mean over the H segments of each group, whose states are one run
            bu = np.add.reduceat(b, self._group_start) / fs.group_count
        if self.alpha is None:
            self.alpha = low.initial()
            if b is not None:
                self.alpha *= b
            self.alpha /= self.alpha.sum()
            self.alpha += ALPHA_FLOOR
            return bu
        # unscaled: off by the common factor a_self, which the normalisation below removes
        pred = low.predict(self.alpha, out=self._pred, work=self._work, scaled=False)
        if b is None:
            c = pred.sum()
        else:
            c = np.dot(pred, b)  # the normaliser without a product array (BLAS)
            pred *= b
        np.multiply(pred, 1.0 / c, out=self.alpha)
        self.alpha += ALPHA_FLOOR
        return bu

    def state_posterior(self) -> np.ndarray:
        """The lower level's forward variable over all frame states (N,) after the last step
        (zero outside the beam)."""
        return self._beam.dense() if self._beam is not None else self.alpha.astype(np.float64)

    @staticmethod
    def _norm(a: np.ndarray) -> np.ndarray:
        s = a.sum()
        return a / s if s > 0 else np.full_like(a, 1.0 / a.size)

    def _interpolate(self, y: np.ndarray | None) -> np.ndarray:
        """Eq. 10-13 in the most probable phase; returns x_bar (dx,)."""
        fs = self.fs
        pp = np.bincount(fs.group_phase, self.alpha_up, minlength=self.upper.num_phases)
        self.phase_posterior = pp
        for h in itertools.chain((int(pp.argmax()),), np.argsort(-pp).tolist()):
            # the lower level may hold no mass in that phase: take the next
            blk_id = self._phase_block.get(h)
            if blk_id is None:
                continue
            _, g0, st, big_h, length = self._blocks[blk_id]
            if self._beam is not None:  # the block's segments in the beam
                segs, frames = self._beam.block_segments(blk_id)      # (m,), (m, L)
            else:
                segs, frames = None, self.alpha[st: st + big_h * length].reshape(
                    length, big_h).T
            w = frames.sum(axis=1)
            if w.size and w.max() > 0:
                break
        self.phase = h
        m = w.size
        k = min(self.m.K, m)
        top = np.arange(m) if k == m else top_segments(w, k)
        idx = top if segs is None else segs[top]
        tot = float(w[top].sum())
        weights = (frames[top] / tot if tot > 0 else
                   np.full((k, length), 1.0 / (k * length))).astype(np.float64)
        rows = (st + self._frame_offsets[blk_id] + idx[:, None]).ravel()      # (K L,)
        x = weights.ravel() @ fs.mu_x.take(rows, axis=0)
        # per frame l: sum_k w_kl mu^Y_kl, one batched product (L, 1, K) @ (L, K, dy)
        wy = np.matmul(weights.T[:, None, :], fs.mu_y.take(rows, axis=0).reshape(
            k, length, -1).swapaxes(0, 1))[:, 0]                               # (L, dy)
        self.y_bar = wy.sum(0)                                              # eq. 10
        wl = weights.sum(0)                                                 # (L,)
        self.variance = wl @ fs.cond_var[g0: g0 + length]                   # eq. 12
        if y is not None:                                                   # eq. 6, 11
            r = np.multiply.outer(wl, y) - wy                               # (L, dy)
            x += self._reg_blocks[blk_id] @ r.ravel()
        return x

    # ---- output -----------------------------------------------------------------------------
    def _pose(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        lay, fps, j = self.lay, self.m.fps_, self.j
        d6 = x[lay["rot6d"]].reshape(j, 6)
        if self.r_prev is not None and self.m.blend < 1.0:
            # velocity-based blending in the 6-D representation: advance the previous pose by
            # the interpolated angular velocity, then move towards the interpolated pose
            pred = self.r_prev @ matrix_exp(x[lay["omega"]].reshape(j, 3) / fps)
            pred6 = pred[:, :, :2].swapaxes(1, 2).reshape(j, 6)  # columns 0 and 1
            d6 = self.m.blend * d6 + (1.0 - self.m.blend) * pred6
        r = matrix_from_6d(d6)
        self.r_prev = r
        height, vx, vz, yaw_rate = x[lay["root"]].tolist()
        if self.t > 0:
            self.theta += yaw_rate / fps
        c, s = math.cos(self.theta), math.sin(self.theta)
        rm = r.copy()
        rm[0] = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]]) @ r[0]  # about +Y
        # root step: the heading-frame velocity turned by the yaw (about +Y), as pose.decode
        sx, sz = ((c * vx + s * vz) / fps, (c * vz - s * vx) / fps) if self.t > 0 else (0.0, 0.0)
        raw = self.root_raw
        raw[0] += sx
        raw[2] += sz
        raw[1] = height
        rot = matrix_to_quat(rm)
        if self.q_prev is not None:  # keep quaternion signs continuous over time
            flip = (rot * self.q_prev) @ _ONES4 < 0
            if flip.any():
                rot[flip] *= -1.0
        self.q_prev = rot
        lo, hi = x[lay["contacts"]].tolist()
        contacts = np.array([min(max(lo, 0.0), 1.0), min(max(hi, 0.0), 1.0)])
        self.contacts = contacts
        if not self.pin:
            return rot, raw.copy()
        return rot, self.pinner.step(raw, self._feet_relative(rm), contacts)

    def _feet_relative(self, rm: np.ndarray) -> np.ndarray:
        """Ankle positions relative to the root (2, 3), world axes; rm : (J, 3, 3) local
        matrices with the root's global. Forward kinematics of the two leg chains only, both
        at once (``pos += G off_j; G = G R_j`` down each chain)."""
        if self._chains is None:
            return self._feet_relative_levels(rm)
        local = rm[self._chains]                          # (2, D, 3, 3)
        g = rm[0]  # (3, 3), broadcast against both chains
        pos = np.zeros((2, 3, 1))
        for d in range(self._chains.shape[1]):
            pos = pos + g @ self._chain_offsets[:, d]
            g = g @ local[:, d]
        return pos[..., 0]

    def _feet_relative_levels(self, rm: np.ndarray) -> np.ndarray:
        """:meth:`_feet_relative` for legs of different depths, one tree level at a time."""
        n = self._legs.size
        glob = np.empty((n, 3, 3))
        pos = np.zeros((n, 3))
        local = rm[self._legs]
        glob[0] = local[0]
        for lvl, par in self._levels:
            gp = glob[par]
            glob[lvl] = gp @ local[lvl]
            pos[lvl] = pos[par] + (gp @ self._leg_offsets[lvl][..., None])[..., 0]
        return pos[self._leg_feet]

    def step(self, sample: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """sample : (6 S,) one sensor frame, NaN when missing -> (rotations (J, 4), root (3,))."""
        y = np.asarray(sample, dtype=np.float64)
        if y.shape != self.y_bar.shape:
            raise ValueError(f"mousas2017 stream: expected a sample of shape {self.y_bar.shape} "
                             f"(6 channels per sensor {self.m.placements_}), got {y.shape}")
        obs = y if np.all(np.isfinite(y)) else None
        if self._k is not None:
            out = self._step_compiled(obs)
            self.t += 1
            return out
        self._filter(obs)
        x = self._interpolate(obs)
        self.pose_vector = x[self.lay["pose"]]
        out = self._pose(x)
        self.t += 1
        return out

    # ---- the compiled step (engine numba) -----------------------------------------------------
    def _compiled_init(self) -> None:
        """Buffers and tables of the compiled step (:mod:`.compiled`)."""
        fs, low = self.fs, self.lower
        dtype = low.dtype
        self._blocks_arr = np.array([(st, big_h, length, g0) for _, g0, st, big_h, length
                                     in self._blocks], dtype=np.int64).reshape(-1, 4)
        self._block_phase = np.array([b[0] for b in self._blocks], dtype=np.int64)
        phase_block = np.full(self.upper.num_phases, -1, dtype=np.int64)
        for i, b in enumerate(self._blocks):
            phase_block[b[0]] = i
        self._phase_block_arr = phase_block
        self._group_count = np.asarray(fs.group_count, dtype=np.int64)
        self._group_start_arr = np.asarray(self._group_start, dtype=np.int64)
        self._group_phase = np.asarray(fs.group_phase, dtype=np.int64)
        fs_, fn, fk, _ = low.frame_weights(scaled=False)
        self._trans_w = np.array([fs_, fn, fk, fn + fk])
        self._quad = np.empty(self._group_count.size, dtype=dtype)
        self._scratch = np.empty(1, dtype=dtype)
        self._bu = np.zeros(self._group_count.size)
        self._floors = (np.asarray(EMISSION_FLOOR, dtype=dtype)[()],
                        np.asarray(ALPHA_FLOOR, dtype=dtype)[()])
        self._prec = np.ascontiguousarray(fs.prec, dtype=np.float64)
        self._reg = np.ascontiguousarray(fs.reg, dtype=np.float64)
        self._cond_var = np.ascontiguousarray(fs.cond_var, dtype=np.float64)
        self._x = np.zeros(fs.mu_x.shape[1])
        # pose state: heading, raw root (3), 1 once there is a previous frame
        self._pose_state = np.zeros(5)
        self._r_prev_arr = np.zeros((self.j, 3, 3))
        self._q_prev_arr = np.zeros((self.j, 4))
        self._rm = np.empty((self.j, 3, 3))
        self._feet = np.zeros((2, 3))
        no_chain = np.zeros((0, 0), dtype=np.int64)
        self._k_chains = no_chain if self._chains is None else self._chains.astype(np.int64)
        self._k_chain_offsets = np.zeros((0, 0, 3)) if self._chains is None else \
            np.ascontiguousarray(self._chain_offsets[..., 0], dtype=np.float64)

    def _step_compiled(self, y: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """One step with the compiled kernels: the same as ``_filter``, ``_interpolate`` and
        ``_pose`` (to float rounding)."""
        k, fs = self._k, self.fs
        has_y = y is not None
        first = self.alpha_up is None
        if first:
            self._filter(y)  # a stream's first step (pi): numpy's
        elif self._beam is not None:
            self._beam.step_compiled(k, y, self._bu)
        else:
            if has_y:
                b = self._b
                fs.linear(y, out=b)
                k.emission(b, y, self._prec, self._quad, self._group_start_arr,
                           self._group_count, b.dtype.type(EXP_CLAMP))
                np.exp(b, out=b)
            k.forward(self.alpha, self._pred, self._b, has_y, self._blocks_arr,
                      self._block_phase, self.lower.phase_trans, self._trans_w, self._bu,
                      self._floors[0], self._floors[1], self._scratch)
        if first and self._beam is not None:
            x = self._interpolate(y)
        elif self._beam is not None:
            bm = self._beam
            self.phase = k.interpolate_beam(
                bm.seg, bm.alpha, bm.block, self.alpha_up, self._a_up, self._bu, has_y, True,
                self._group_phase, self._phase_block_arr, self._blocks_arr, bm.seg0, self.m.K,
                TIE_RTOL, fs.mu_x, fs.mu_y, self._reg, self._cond_var,
                y if has_y else self.y_bar, self.phase_posterior, self._x, self.y_bar,
                self.variance)
            x = self._x
        else:
            self.phase = k.interpolate(
                self.alpha, self.alpha_up, self._a_up, self._bu, has_y, not first,
                self._group_phase, self._phase_block_arr, self._blocks_arr, self.m.K,
                TIE_RTOL, fs.mu_x, fs.mu_y, self._reg, self._cond_var,
                y if has_y else self.y_bar, self.phase_posterior, self._x, self.y_bar,
                self.variance)
            x = self._x
        self.pose_vector = x[self.lay["pose"]].copy()
        rot = np.empty((self.j, 4))
        contacts = np.empty(2)
        k.pose(x, self.j, float(self.m.blend), float(self.m.fps_), self.t, self._pose_state,
               self._r_prev_arr, self._q_prev_arr, _SHEPPERD[0], _SHEPPERD[1], self._k_chains,
               self._k_chain_offsets, rot, self._rm, contacts, self._feet)
        self.contacts = contacts
        raw = self._pose_state[1:4]
        if not self.pin:
            return rot, raw.copy()
        feet = self._feet if self._chains is not None else self._feet_relative_levels(self._rm)
        return rot, self.pinner.step(raw, feet, contacts)
