"""Compiled kernels of the online stream's step (numba, the ``fast`` extra).

The numpy step of :mod:`.stream` makes about 150 numpy calls a frame on arrays of a few dozen
joints and 15 passes over the N frame states; each call costs microseconds on its own. These
kernels do the same arithmetic in a few compiled loops, called once a frame each:

- :func:`emission`: eq. 9's quadratic term per group subtracted from ``y_aug @ lin_aug`` (that
  product stays numpy's, one BLAS call), the maximum subtracted, the clamp of
  :data:`.stream.EXP_CLAMP`; ``exp`` stays numpy's too;
- :func:`forward`: the emission floor, eq. 8's mean per group, one transition of
  :meth:`.forward.Topology.predict` (unscaled), the product with the emission, the
  normalisation and the forward floor: two passes over the states;
- :func:`interpolate`: the upper level's dense step, the phase posterior and eq. 10-13;
- :func:`pose`: velocity-based blending, Gram-Schmidt, root decoding, quaternions and the legs'
  forward kinematics for the foot clean-up;
- with a beam (:mod:`.beam`): :func:`beam_step`, the beam's whole step (transitions of the
  kept segments, their emissions and every first frame's, the entrants, eq. 8, the selection
  of the ``width`` segments by :func:`keep_largest`), and :func:`interpolate_beam`.

Element operations are those of the numpy step in the forward variable's precision (float32
in a fitted model); sums accumulate in float64, where numpy's float32 reductions (BLAS dot,
``reduceat``) round in another order. So a float32 forward variable agrees with the numpy
step's to float32 rounding and a float64 one to about 1e-15 (tests/test_mousas2017.py).
Hand-written because this step is the method's own (see :mod:`.forward`); numba only compiles
it. Importing this module needs numba (:func:`.stream.compiled_kernels` says which extra);
each kernel is compiled on first use and cached on disk (numba's ``cache=True``: beside this
file, or in the user's cache directory when the installation is read-only), so the compile
cost is paid once per machine, not per stream.
"""

from __future__ import annotations

import numpy as np
from numba import njit

# error_model="numpy": a division by zero gives inf, as numpy's, not an exception check per
# division
_jit = njit(cache=True, nogil=True, error_model="numpy")
# sums over the states in any order (vectorised); element operations stay as written
_jit_sums = njit(cache=True, nogil=True, error_model="numpy", fastmath={"reassoc"})
# and a maximum in any order (no NaN: the emission's inputs are finite)
_jit_max = njit(cache=True, nogil=True, error_model="numpy",
                fastmath={"reassoc", "nnan", "nsz"})


# ---- the lower level's forward step --------------------------------------------------------
@_jit
def _quad(prec, y, quad):
    """Each group's ``y' P_g y / 2`` into ``quad`` (G,); prec : (G, dy, dy); y : (dy,) or
    longer (its first dy entries)."""
    dy = prec.shape[1]
    for g in range(prec.shape[0]):
        q = 0.0
        for d in range(dy):
            s = 0.0
            for e in range(dy):
                s += prec[g, d, e] * y[e]
            q += s * (0.5 * y[d])
        quad[g] = q


@_jit_max
def emission(b, y, prec, quad, group_start, group_count, clamp):
    """In place: ``b`` (N,) holds ``m_i . y + c_i`` (:meth:`.model.FrameStates.log_emission`
    before its quadratic term); subtracts each group's ``y' P_g y / 2``, then the maximum, and
    raises values below ``clamp`` to it. y : (dy,) float64; prec : (G, dy, dy); quad : (G,)
    scratch of b's dtype."""
    num_g = prec.shape[0]
    _quad(prec, y, quad)
    top = b[0] - quad[0]
    for g in range(num_g):
        q32 = quad[g]
        run = b[group_start[g]: group_start[g] + group_count[g]]
        for i in range(run.size):
            v = run[i] - q32
            run[i] = v
            top = max(top, v)
    for i in range(b.size):
        v = b[i] - top
        b[i] = max(v, clamp)


@_jit
def _vm(v, m):
    """v @ m for a small matrix m (numba's @ calls BLAS, slow at this size)."""
    out = np.zeros(m.shape[1])
    for i in range(m.shape[0]):
        for j in range(m.shape[1]):
            out[j] += v[i] * m[i, j]
    return out


@_jit_sums
def forward(alpha, pred, b, has_b, blocks, block_phase, phase_trans, weights, bu,
            emission_floor, alpha_floor, scratch):
    """One exact forward step of the lower level, in place, as the numpy step's
    ``_filter_exact`` after its first frame.

    alpha : (N,) the forward variable, replaced by the new one; pred : (N,) scratch;
    b : (N,) ``exp(log b_i - max)`` (its floor is added here), ignored unless ``has_b``;
    blocks : (B, 4) int, (first state, H, L, first group) of each phase block;
    block_phase : (B,) int; phase_trans : (P, P) the topology's ``phase_trans``;
    weights : (4,) float64 of the transition without its common factor ``a_self`` (self,
    next, skip, next + skip; :meth:`.forward.Topology.predict`, ``scaled=False``);
    bu : (G,) float64, set to the upper level's emission (eq. 8); scratch : (1,) of alpha's
    dtype (casts Python-float constants to it, as numpy does).
    """
    a_self, a_next, a_skip = weights[0], weights[1], weights[2]
    scratch[0] = a_self
    ws = scratch[0]
    scratch[0] = a_next
    wn = scratch[0]
    scratch[0] = a_skip
    wk = scratch[0]
    num_b, num_p = blocks.shape[0], phase_trans.shape[0]
    # mass that moves past the last frame ends a segment: the upper level's entries
    out_phase = np.zeros(num_p)
    for k in range(num_b):
        st, big_h, length = blocks[k, 0], blocks[k, 1], blocks[k, 2]
        last = st + (length - 1) * big_h
        s_last = 0.0
        for i in range(last, last + big_h):
            s_last += alpha[i]
        s_prev = 0.0
        if length >= 2:
            for i in range(last - big_h, last):
                s_prev += alpha[i]
        out_phase[block_phase[k]] = s_last * weights[3] + s_prev * a_skip
    entry = _vm(out_phase, phase_trans)
    c = 0.0
    for k in range(num_b):
        st, big_h, length, g0 = blocks[k, 0], blocks[k, 1], blocks[k, 2], blocks[k, 3]
        scratch[0] = entry[block_phase[k]] / big_h
        e = scratch[0]
        for j in range(length):
            # views of one frame run and the runs before it: loops over 0..H with indices the
            # compiler knows are >= 0 (no negative-index wrap-around check), so they vectorise
            lo = st + j * big_h
            out, a0 = pred[lo: lo + big_h], alpha[lo: lo + big_h]
            if j == 0:  # pi: each segment's first frame alike
                for i in range(big_h):
                    out[i] = a0[i] * ws + e
            elif j == 1 or a_skip == 0.0:  # the next frame
                a1 = alpha[lo - big_h: lo]
                for i in range(big_h):
                    out[i] = a0[i] * ws + a1[i] * wn
            else:  # and the skip
                a1, a2 = alpha[lo - big_h: lo], alpha[lo - 2 * big_h: lo - big_h]
                for i in range(big_h):
                    out[i] = a0[i] * ws + a1[i] * wn + a2[i] * wk
            if has_b:
                bj = b[lo: lo + big_h]
                total = 0.0
                for i in range(big_h):
                    bi = bj[i] + emission_floor
                    total += bi
                    p = out[i] * bi
                    out[i] = p
                    c += p
                bu[g0 + j] = total / big_h
            else:
                for i in range(big_h):
                    c += out[i]
    scratch[0] = 1.0 / c
    inv = scratch[0]
    for i in range(alpha.size):
        alpha[i] = pred[i] * inv + alpha_floor


# ---- eq. 10-13 -------------------------------------------------------------------------------
@_jit
def _upper(alpha_up, a_up, bu, has_y, step_up, group_phase, pp):
    """The upper level's dense step (when ``step_up``) and the phase posterior ``pp`` (P,), in
    place; returns the phases, most probable first."""
    if step_up:
        up = _vm(alpha_up, a_up)
        c = 0.0
        if has_y:
            up2 = up * bu
            c = up2.sum()
        if c > 0:
            alpha_up[:] = up2 / c
        else:
            c = up.sum()
            if c > 0:
                alpha_up[:] = up / c
            else:
                alpha_up[:] = 1.0 / alpha_up.size
    pp[:] = 0.0
    for g in range(alpha_up.size):
        pp[group_phase[g]] += alpha_up[g]
    return np.argsort(-pp, kind="mergesort")


@_jit
def _top(w, top_k, tie_rtol):
    """The K = min(top_k, n) largest of the segment masses w (n,) (:func:`_largest`) and
    their sum."""
    top = _largest(w, min(top_k, w.size), tie_rtol)
    tot = 0.0
    for s in top:
        tot += w[s]
    return top, tot


@_jit
def _blend(frames, rows, tot, g0, has_y, mu_x, mu_y, reg, cond_var, y, x, y_bar, variance):
    """Eq. 10-13 over K segments of one block: ``frames`` (K, L) their frames' forward
    probabilities, summing to ``tot``; ``rows`` (K, L) their frame states; g0 the block's
    first group. Sets ``x`` (dx,), ``y_bar`` (dy,), ``variance`` (dx,)."""
    k, length = frames.shape
    dx, dy = mu_x.shape[1], mu_y.shape[1]
    x[:] = 0.0
    y_bar[:] = 0.0
    variance[:] = 0.0
    wl = np.zeros(length)
    wy = np.zeros((length, dy))
    for i in range(k):
        for j in range(length):
            row = rows[i, j]
            wt = frames[i, j] / tot if tot > 0 else 1.0 / (k * length)
            wl[j] += wt
            for d in range(dx):
                x[d] += wt * mu_x[row, d]
            for d in range(dy):
                wy[j, d] += wt * mu_y[row, d]
    for j in range(length):
        for d in range(dy):
            y_bar[d] += wy[j, d]                                            # eq. 10
        for d in range(dx):
            variance[d] += wl[j] * cond_var[g0 + j, d]                     # eq. 12
        if has_y:                                                           # eq. 6, 11
            for d in range(dy):
                r = wl[j] * y[d] - wy[j, d]
                for e in range(dx):
                    x[e] += reg[g0 + j, e, d] * r


@_jit
def interpolate(alpha, alpha_up, a_up, bu, has_y, step_up, group_phase, phase_block, blocks,
                top_k, tie_rtol, mu_x, mu_y, reg, cond_var, y, pp, x, y_bar, variance):
    """The upper level's step (dense, G states; when ``step_up``), then eq. 10-13 in the most
    probable phase that holds lower-level mass, as the numpy step's ``_filter`` (upper part)
    and ``_interpolate``. In place: ``alpha_up`` (G,), ``pp`` (P,) the phase posterior, ``x``
    (dx,) the interpolated features, ``y_bar`` (dy,), ``variance`` (dx,). Returns the phase.

    alpha : (N,) the lower level's forward variable; a_up : (G, G); bu : (G,) eq. 8;
    has_y : a sample (y, bu) is given, else only transitions and means; phase_block : (P,)
    block of each phase, -1 for none; blocks : as :func:`forward`; mu_x : (N, dx);
    mu_y : (N, dy); reg : (G, dx, dy); cond_var : (G, dx); y : (dy,) the sample;
    top_k, tie_rtol : K and the ties of :func:`.stream.top_segments`.
    """
    order = _upper(alpha_up, a_up, bu, has_y, step_up, group_phase, pp)
    # the most probable phase whose block holds mass
    blk, w = -1, np.zeros(0)
    phase = int(order[0])
    for h in order:
        k = phase_block[h]
        if k < 0:
            continue
        st, big_h, length = blocks[k, 0], blocks[k, 1], blocks[k, 2]
        w = np.zeros(big_h)
        for j in range(length):
            for s in range(big_h):
                w[s] += alpha[st + j * big_h + s]
        blk, phase = k, int(h)
        if w.max() > 0:
            break
    st, big_h, length, g0 = blocks[blk, 0], blocks[blk, 1], blocks[blk, 2], blocks[blk, 3]
    top, tot = _top(w, top_k, tie_rtol)
    k = top.size
    frames = np.empty((k, length))
    rows = np.empty((k, length), dtype=np.int64)
    for i in range(k):
        for j in range(length):
            rows[i, j] = st + j * big_h + top[i]
            frames[i, j] = alpha[rows[i, j]]
    _blend(frames, rows, tot, g0, has_y, mu_x, mu_y, reg, cond_var, y, x, y_bar, variance)
    return phase


@_jit
def interpolate_beam(seg, seg_alpha, seg_block, alpha_up, a_up, bu, has_y, step_up,
                     group_phase, phase_block, blocks, seg0, top_k, tie_rtol, mu_x, mu_y, reg,
                     cond_var, y, pp, x, y_bar, variance):
    """:func:`interpolate` with the lower level's forward variable in a beam
    (:class:`.beam.SegmentBeam`: ``seg`` (n,) kept segments, ``seg_alpha`` (n, W) their
    frames'; ``seg_block`` (S,) block of each segment, ``seg0`` (B,) first segment of each
    block), as the numpy step's ``_interpolate`` with a beam: the top K of the block's kept
    segments, in the order of their index."""
    order = _upper(alpha_up, a_up, bu, has_y, step_up, group_phase, pp)
    blk, w, mine = -1, np.zeros(0), np.zeros(0, dtype=np.int64)
    phase = int(order[0])
    for h in order:
        k = phase_block[h]
        if k < 0:
            continue
        length = blocks[k, 2]
        mine = np.flatnonzero(seg_block[seg] == k)
        mine = mine[np.argsort(seg[mine])]
        w = np.zeros(mine.size)
        for i in range(mine.size):
            for j in range(length):
                w[i] += seg_alpha[mine[i], j]
        blk, phase = k, int(h)
        if w.size and w.max() > 0:
            break
    st, big_h, length, g0 = blocks[blk, 0], blocks[blk, 1], blocks[blk, 2], blocks[blk, 3]
    top, tot = _top(w, top_k, tie_rtol)
    k = top.size
    frames = np.empty((k, length))
    rows = np.empty((k, length), dtype=np.int64)
    for i in range(k):
        r = mine[top[i]]
        for j in range(length):
            rows[i, j] = st + j * big_h + seg[r] - seg0[blk]
            frames[i, j] = seg_alpha[r, j]
    _blend(frames, rows, tot, g0, has_y, mu_x, mu_y, reg, cond_var, y, x, y_bar, variance)
    return phase


@_jit
def _largest(w, k, tie_rtol):
    """Indices of the k largest entries of w (n,), k <= n, as :func:`.stream.top_segments`:
    those above the k-th largest by more than ``tie_rtol`` (relative), then the lowest indices
    among the ties. O(n k) (k is small: K = 5)."""
    top = np.empty(k, dtype=np.int64)
    m = 0
    for s in range(w.size):  # the k largest, by insertion
        if m < k:
            pos = m
            m += 1
        elif w[s] > w[top[k - 1]]:
            pos = k - 1
        else:
            continue
        while pos > 0 and w[top[pos - 1]] < w[s]:
            top[pos] = top[pos - 1]
            pos -= 1
        top[pos] = s
    if k == w.size:
        return top
    thr = w[top[k - 1]]
    lo, hi = thr * (1.0 - tie_rtol), thr * (1.0 + tie_rtol)
    m = 0
    for s in range(w.size):
        if w[s] > hi:
            top[m] = s
            m += 1
    for s in range(w.size):
        if m == k:
            break
        if lo <= w[s] <= hi:
            top[m] = s
            m += 1
    return top


# ---- the pose ------------------------------------------------------------------------------
@_jit
def _from_6d(d6, out):
    """6-D rotations (J, 6) -> matrices (J, 3, 3) in ``out``, as :func:`.stream.matrix_from_6d`."""
    for i in range(d6.shape[0]):
        n = np.sqrt(d6[i, 0] ** 2 + d6[i, 1] ** 2 + d6[i, 2] ** 2)
        a0, a1, a2 = d6[i, 0] / n, d6[i, 1] / n, d6[i, 2] / n
        dot = a0 * d6[i, 3] + a1 * d6[i, 4] + a2 * d6[i, 5]
        b0, b1, b2 = d6[i, 3] - dot * a0, d6[i, 4] - dot * a1, d6[i, 5] - dot * a2
        n = np.sqrt(b0 * b0 + b1 * b1 + b2 * b2)
        b0, b1, b2 = b0 / n, b1 / n, b2 / n
        out[i, 0, 0], out[i, 1, 0], out[i, 2, 0] = a0, a1, a2
        out[i, 0, 1], out[i, 1, 1], out[i, 2, 1] = b0, b1, b2
        out[i, 0, 2] = a1 * b2 - a2 * b1
        out[i, 1, 2] = a2 * b0 - a0 * b2
        out[i, 2, 2] = a0 * b1 - a1 * b0


@_jit
def _mm3(a, b, out):
    """out = a @ b for 3 x 3 matrices (numba's @ calls BLAS, slow at this size)."""
    for i in range(3):
        for j in range(3):
            out[i, j] = a[i, 0] * b[0, j] + a[i, 1] * b[1, j] + a[i, 2] * b[2, j]


@_jit
def _exp_map(r0, r1, r2, k, kk, out):
    """A rotation vector -> its matrix in ``out`` (3, 3), as :func:`.stream.matrix_exp`;
    k, kk : (3, 3) scratch."""
    a = np.sqrt(r0 * r0 + r1 * r1 + r2 * r2) + 1e-300
    s, h = np.sin(a) / a, np.sin(0.5 * a) / a
    h2 = 2.0 * h * h
    k[0, 0], k[0, 1], k[0, 2] = 0.0, -r2, r1
    k[1, 0], k[1, 1], k[1, 2] = r2, 0.0, -r0
    k[2, 0], k[2, 1], k[2, 2] = -r1, r0, 0.0
    _mm3(k, k, kk)
    for i in range(3):
        for j in range(3):
            out[i, j] = (1.0 if i == j else 0.0) + s * k[i, j] + h2 * kk[i, j]


@_jit
def pose(x, num_joints, blend, fps, t, state, r_prev, q_prev, shepperd, shepperd_c, chains,
         chain_offsets, rot, rm, contacts, feet):
    """Eq. 13's pose vector ``x`` (dx,) to the frame's output, as the numpy step's ``_pose``.

    state : (5,) float64 in place: heading theta, the raw root (3), and 1 once ``r_prev``
    and ``q_prev`` hold a previous frame; r_prev : (J, 3, 3), q_prev : (J, 4) in place;
    shepperd, shepperd_c : :data:`.stream._SHEPPERD`; chains : (2, D) joints from below the
    root to each ankle; chain_offsets : (2, D, 3) (no rows: no chains, ``feet`` untouched).
    Out: rot (J, 4) quaternions x, y, z, w; rm (J, 3, 3) local matrices with the root's
    global; contacts (2,); feet (2, 3) ankles relative to the root, world axes.
    """
    j6 = 6 * num_joints
    d6 = x[:j6].copy().reshape(num_joints, 6)
    has_prev = state[4] > 0
    e, p, k, kk = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
    if has_prev and blend < 1.0:
        for i in range(num_joints):
            o = j6 + 4 + 3 * i
            _exp_map(x[o] / fps, x[o + 1] / fps, x[o + 2] / fps, k, kk, e)
            _mm3(r_prev[i], e, p)
            for c in range(3):
                d6[i, c] = blend * d6[i, c] + (1.0 - blend) * p[c, 0]
                d6[i, 3 + c] = blend * d6[i, 3 + c] + (1.0 - blend) * p[c, 1]
    _from_6d(d6, rm)
    r_prev[:] = rm
    height, vx, vz, yaw_rate = x[j6], x[j6 + 1], x[j6 + 2], x[j6 + 3]
    if t > 0:
        state[0] += yaw_rate / fps
    c, s = np.cos(state[0]), np.sin(state[0])
    for j in range(3):  # the root's about +Y
        rm[0, 0, j] = c * r_prev[0, 0, j] + s * r_prev[0, 2, j]
        rm[0, 2, j] = -s * r_prev[0, 0, j] + c * r_prev[0, 2, j]
    if t > 0:
        state[1] += (c * vx + s * vz) / fps
        state[3] += (c * vz - s * vx) / fps
    state[2] = height
    kq = np.empty(16)
    for i in range(num_joints):  # Shepperd: K = m C + c, its row of largest diagonal entry
        for m in range(16):
            v = shepperd_c[m]
            for n in range(9):
                v += rm[i, n // 3, n % 3] * shepperd[n, m]
            kq[m] = v
        best = 0
        for m in range(1, 4):
            if kq[5 * m] > kq[5 * best]:
                best = m
        n = np.sqrt(kq[4 * best] ** 2 + kq[4 * best + 1] ** 2 + kq[4 * best + 2] ** 2
                    + kq[4 * best + 3] ** 2)
        for m in range(4):
            rot[i, m] = kq[4 * best + m] / n
        if has_prev and (rot[i, 0] * q_prev[i, 0] + rot[i, 1] * q_prev[i, 1]
                         + rot[i, 2] * q_prev[i, 2] + rot[i, 3] * q_prev[i, 3]) < 0:
            for m in range(4):
                rot[i, m] = -rot[i, m]
    q_prev[:] = rot
    state[4] = 1.0
    lo, hi = x[j6 + 4 + 3 * num_joints], x[j6 + 5 + 3 * num_joints]
    contacts[0], contacts[1] = min(max(lo, 0.0), 1.0), min(max(hi, 0.0), 1.0)
    for f in range(chains.shape[0]):  # the legs' kinematics: pos += G off_j; G = G R_j
        e[:] = rm[0]
        for j in range(3):
            feet[f, j] = 0.0
        for d in range(chains.shape[1]):
            off = chain_offsets[f, d]
            for j in range(3):
                feet[f, j] += e[j, 0] * off[0] + e[j, 1] * off[1] + e[j, 2] * off[2]
            _mm3(e, rm[chains[f, d]], p)
            e[:] = p


# ---- the beam's step (:mod:`.beam`) ----------------------------------------------------------
@_jit
def kth_largest(v, k):
    """The k-th largest of v (n,) float64 >= 0 (no NaN), 0 < k <= n: a radix select on the
    floats' bits, which order as the values for non-negative floats (11 bits a pass, each pass
    over the values left in the bucket of the k-th). Hand-written: numba's ``np.partition``
    takes 4-7 times longer than this on the beam's 10^4 values."""
    cand = v.view(np.int64)
    hist = np.empty(2048, dtype=np.int64)
    shift = 52
    while cand.size > 32:
        hist[:] = 0
        for i in range(cand.size):
            hist[(cand[i] >> shift) & 2047] += 1
        e = 2047
        while hist[e] < k:
            k -= hist[e]
            e -= 1
        sub = np.empty(hist[e], dtype=np.int64)
        m = 0
        for i in range(cand.size):
            if (cand[i] >> shift) & 2047 == e:
                sub[m] = cand[i]
                m += 1
        cand = sub
        if shift == 0:
            break
        shift = max(shift - 11, 0)
    s = np.sort(cand)
    return s.view(np.float64)[s.size - k]


@_jit
def keep_largest(v, k, tie_rtol):
    """Mask of the k largest entries of v (n,) >= 0, 0 < k <= n, as
    :func:`.beam.keep_largest`: those above the k-th largest by more than ``tie_rtol``
    (relative), then the lowest indices among the ties. O(n)."""
    thr = kth_largest(v, k)
    lo, hi = thr * (1.0 - tie_rtol), thr * (1.0 + tie_rtol)
    keep = v > hi
    room = k - keep.sum()
    for i in range(v.size):
        if room == 0:
            break
        if not keep[i] and v[i] >= lo:
            keep[i] = True
            room -= 1
    return keep


@_jit_max
def beam_step(seg, alpha, has_y, y_aug, prec, quad, lin, first_lin, group, first_group,
              seg0, seg_block, seg_len, block_phase, counts, phase_trans, a_frame,
              group_count, width, emission_floor, alpha_floor, tie_rtol, member, bu):
    """One step of :class:`.beam.SegmentBeam` after its first, as its numpy ``step``: returns
    the new kept segments (n',), their forward probabilities (n', W) and masses (n',).

    seg : (n,) kept segments; alpha : (n, W) their frames' forward probabilities (float64);
    has_y : a sample is given (``y_aug`` (dy + 1,) the sample and 1, in lin's dtype), else
    transitions only; prec : (G, dy, dy); quad : (G + 1,) scratch of lin's dtype whose last
    entry is inf; lin : (S, W, dy + 1) the beam's ``lin``; first_lin : (dy + 1, S);
    group : (S, W), first_group : (S,) groups (G in the padding); seg0 : (B,) first segment of
    each block; seg_block, seg_len : (S,) block and length of each segment; block_phase : (B,);
    counts : (B,) segments per block; phase_trans : (P, P); a_frame : (3,) (self, next, skip);
    group_count : (G,) float64; member : (S,) bool, True on the kept segments, updated;
    bu : (G,) set to eq. 8's emission when ``has_y``.
    """
    n, w_ = alpha.shape
    num_s, num_b, num_g = first_lin.shape[1], counts.size, group_count.size
    fs_, fn, fk = a_frame[0], a_frame[1], a_frame[2]
    # 1. the kept segments' mass moved one frame; what moves into the padding ends them
    pred = np.empty((n, w_))
    out_phase = np.zeros(phase_trans.shape[0])
    for r in range(n):
        s = seg[r]
        length = seg_len[s]
        ended = 0.0
        for j in range(w_):
            v = alpha[r, j] * fs_
            if j >= 1:
                v += fn * alpha[r, j - 1]
            if j >= 2:
                v += fk * alpha[r, j - 2]
            if j < length:
                pred[r, j] = v
            else:
                pred[r, j] = 0.0
                ended += v
        out_phase[block_phase[seg_block[s]]] += ended
    up = _vm(out_phase, phase_trans)
    entry = np.empty(num_b)
    for b in range(num_b):
        entry[b] = up[block_phase[b]] / counts[b]
    for r in range(n):
        pred[r, 0] += entry[seg_block[seg[r]]]
    # 2. emissions of the kept frames and of every first frame, relative to their best
    floor = emission_floor if has_y else 0.0
    limit = np.zeros(num_b)
    raw = np.zeros(num_s)
    ll = np.full((n, w_), -np.inf)  # log b, then b (kept frames)
    a = pred
    if has_y:
        dy = prec.shape[1]
        _quad(prec, y_aug, quad)
        top = -np.inf
        for r in range(n):
            s = seg[r]
            for j in range(seg_len[s]):
                t = 0.0
                for d in range(dy + 1):
                    t += lin[s, j, d] * y_aug[d]
                v = t - quad[group[s, j]]
                ll[r, j] = v
                top = max(top, v)
        for d in range(dy + 1):
            yd = y_aug[d]
            row = first_lin[d]
            for s in range(num_s):
                raw[s] += row[s] * yd
        for b in range(num_b):
            best = -np.inf
            for s in range(seg0[b], seg0[b] + counts[b]):
                best = max(best, raw[s])
            top = max(top, best - quad[first_group[seg0[b]]])
        for b in range(num_b):
            limit[b] = quad[first_group[seg0[b]]] + top
        a = np.zeros((n, w_))  # zero in the padding, where pred is
        for r in range(n):
            for j in range(seg_len[seg[r]]):
                ll[r, j] = np.exp(ll[r, j] - top) + floor
                a[r, j] = pred[r, j] * ll[r, j]
    mass = np.empty(n)
    for r in range(n):
        t = 0.0
        for j in range(w_):
            t += a[r, j]
        mass[r] = t
    # 3. segments outside the beam whose entry mass times first frame's emission reaches the
    # width-th largest kept mass
    thr = (mass.min() if n == width else kth_largest(mass, width)) if n >= width else 0.0
    lim = np.empty(num_b)
    for b in range(num_b):
        if entry[b] > 0:
            need = thr / entry[b] - floor
            lim[b] = (np.log(need) if need > 0 else -np.inf) + limit[b]
        else:
            lim[b] = np.inf
    num_new = 0
    new = np.empty(num_s, dtype=np.int64)
    for b in range(num_b):
        lo, hi = seg0[b], seg0[b] + counts[b]
        if not has_y:  # every segment of the block or none
            if lim[b] <= 0.0:
                for s in range(lo, hi):
                    if not member[s]:
                        new[num_new] = s
                        num_new += 1
            continue
        limb = lim[b]
        for s in range(lo, hi):
            if raw[s] >= limb and not member[s]:
                new[num_new] = s
                num_new += 1
    new = new[:num_new]
    new_b = np.ones(num_new)
    if has_y:
        for i in range(num_new):
            s = new[i]
            new_b[i] = np.exp(raw[s] - limit[seg_block[s]]) + floor
        # eq. 8: the mean over each group's segments, the frames not computed at the floor
        num = np.zeros(num_g)
        cnt = np.zeros(num_g)
        for r in range(n):
            s = seg[r]
            for j in range(seg_len[s]):
                num[group[s, j]] += ll[r, j]
                cnt[group[s, j]] += 1.0
        for i in range(num_new):
            g = first_group[new[i]]
            num[g] += new_b[i]
            cnt[g] += 1.0
        for g in range(num_g):
            bu[g] = (num[g] + (group_count[g] - cnt[g]) * emission_floor) / group_count[g]
    # 4. keep the width segments of largest mass, renormalised
    vals = np.empty(n + num_new)
    vals[:n] = mass
    for i in range(num_new):
        vals[n + i] = entry[seg_block[new[i]]] * new_b[i]
    keep = keep_largest(vals, min(width, vals.size), tie_rtol)
    m = keep.sum()
    out_seg = np.empty(m, dtype=np.int64)
    out_a = np.zeros((m, w_))
    out_mass = np.empty(m)
    r2 = 0
    for r in range(n + num_new):
        if keep[r]:
            if r < n:
                out_seg[r2] = seg[r]
                for j in range(w_):
                    out_a[r2, j] = a[r, j]
            else:
                out_seg[r2] = new[r - n]
                out_a[r2, 0] = vals[r]
            out_mass[r2] = vals[r]
            r2 += 1
    c = 0.0
    for r in range(m):
        c += out_mass[r]
    if not c > 0:  # every kept state impossible at float precision: spread evenly
        c = 0.0
        for r in range(m):
            out_a[r, :] = 0.0
            out_a[r, :seg_len[out_seg[r]]] = 1.0
            out_mass[r] = seg_len[out_seg[r]]
            c += out_mass[r]
    for r in range(m):
        out_mass[r] /= c
        for j in range(seg_len[out_seg[r]]):
            out_a[r, j] = out_a[r, j] / c + alpha_floor
    for r in range(n):
        member[seg[r]] = False
    for r in range(m):
        member[out_seg[r]] = True
    return out_seg, out_a, out_mass
