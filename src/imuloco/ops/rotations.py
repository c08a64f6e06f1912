"""Rotation conversions and quaternion algebra that broadcast over leading dimensions.

Quaternions are scipy's order, ``(x, y, z, w)``, unit norm, and act on column vectors
(``qrot(q, v) = R(q) @ v``). Conversions go through :class:`scipy.spatial.transform.Rotation`,
which only takes 1-D batches: these wrappers flatten and restore the leading dimensions.
The products (:func:`qmul`, :func:`qrot`) are written out in numpy because scipy builds a
``Rotation`` object per call, which costs more than the arithmetic in per-frame loops.
"""

from __future__ import annotations

import functools
import inspect
import warnings
from types import ModuleType

import numpy as np

IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])


def _transform() -> ModuleType:
    """:mod:`scipy.spatial.transform` (``Rotation``, ``Slerp``), imported on first use:
    importing it takes 0.7 CPU s, and reading a motion file (``imuloco info FILE``) needs none
    of it."""
    from scipy.spatial import transform  # start-up time (issue #43): see the docstring

    return transform


def _apply(fn, x: np.ndarray, tail: int) -> np.ndarray:
    """Call ``fn`` on ``x`` reshaped to ``(N, *trailing)`` and restore the leading dimensions."""
    x = np.asarray(x, dtype=np.float64)
    lead = x.shape[: x.ndim - tail]
    out = fn(x.reshape((-1,) + x.shape[x.ndim - tail:]))
    return out.reshape(lead + out.shape[1:])


def normalize(q: np.ndarray) -> np.ndarray:
    """Unit quaternions. q : (..., 4)."""
    q = np.asarray(q, dtype=np.float64)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product ``a * b`` (apply ``b`` first, then ``a``). a, b : (..., 4) x,y,z,w."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    ax, ay, az, aw = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bx, by, bz, bw = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return np.stack([
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    ], axis=-1)


def qinv(q: np.ndarray) -> np.ndarray:
    """Inverse of unit quaternions (the conjugate). q : (..., 4)."""
    q = np.asarray(q, dtype=np.float64)
    return q * np.array([-1.0, -1.0, -1.0, 1.0])


def qrot(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors by unit quaternions. q : (..., 4), v : (..., 3) -> (..., 3)."""
    q = np.asarray(q, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    u, w = q[..., :3], q[..., 3:]
    t = 2.0 * cross(u, v)
    return v + w * t + cross(u, t)


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.cross`` of (..., 3) vectors, the same products and differences without its
    per-call overhead (60 us in numpy 2.0, more than the arithmetic for a clip's frames)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def angle(q: np.ndarray) -> np.ndarray:
    """Rotation angle in radians, in [0, pi]. q : (..., 4) -> (...)."""
    q = np.asarray(q, dtype=np.float64)
    return 2.0 * np.arctan2(np.linalg.norm(q[..., :3], axis=-1), np.abs(q[..., 3]))


def geodesic(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Geodesic distance (radians) between rotations. a, b : (..., 4) -> (...)."""
    return angle(qmul(qinv(a), b))


def continuous(q: np.ndarray, axis: int = 0) -> np.ndarray:
    """Flip signs along ``axis`` (time) so consecutive quaternions lie in one hemisphere."""
    q = np.moveaxis(np.array(q, dtype=np.float64), axis, 0)
    dots = np.sum(q[1:] * q[:-1], axis=-1)
    flips = np.cumprod(np.where(dots < 0, -1.0, 1.0), axis=0)
    q[1:] *= flips[..., None]
    return np.moveaxis(q, 0, axis)


# q * e_axis for a pure unit quaternion e_axis (the Hamilton product of qmul with b = e_axis):
# the components of q permuted, with signs. Used by from_euler.
_TIMES_AXIS = {"X": ([3, 2, 1, 0], np.array([1.0, 1.0, -1.0, -1.0])),
               "Y": ([2, 3, 0, 1], np.array([-1.0, 1.0, 1.0, -1.0])),
               "Z": ([1, 0, 3, 2], np.array([1.0, -1.0, 1.0, -1.0]))}


def from_euler(angles: np.ndarray, order: str, degrees: bool = True) -> np.ndarray:
    """Intrinsic Euler angles to quaternions. angles : (..., len(order)) in the order of
    ``order`` (e.g. ``"ZXY"``: rotate about Z, then the new X, then the new Y, as BVH does).

    The product of the axis rotations, first axis outermost, in numpy: the same numbers as
    scipy's ``Rotation.from_euler`` (bit for bit but the sign of zeros, measured) at a tenth of
    its time (scipy 1.17 spends ~1 us a rotation even batched, which dominated reading motion
    files); see :func:`euler_components`."""
    order = check_order(order)
    half = np.asarray(angles, dtype=np.float64) * (np.pi / 360.0 if degrees else 0.5)
    if half.shape[-1:] != (len(order),):
        raise ValueError(f"angles must end in an axis of {len(order)}, got {half.shape}")
    half = np.ascontiguousarray(np.moveaxis(half, -1, 0))  # (len(order), ...)
    out = np.empty(half.shape[1:] + (4,))
    for k, part in enumerate(euler_components(np.sin(half), np.cos(half), order)):
        out[..., k] = part
    return out


def check_order(order: str) -> str:
    """An Euler ``order`` in capitals, 1 to 3 of the axes X, Y, Z; else a ValueError."""
    order = order.upper()
    if not order or len(order) > 3 or any(a not in "XYZ" for a in order):
        raise ValueError(f"order must be 1 to 3 of the axes X, Y, Z, got {order!r}")
    return order


def euler_components(sin: np.ndarray, cos: np.ndarray, order: str
                     ) -> list[np.ndarray | float]:
    """The quaternion components x, y, z, w of intrinsic Euler rotations, given the sines and
    cosines of the half angles, ``sin`` and ``cos`` (len(order), ...) (0.0 for a component
    known to be zero): the core of :func:`from_euler`, for callers that lay the angles out
    themselves. Each factor ``cos + sin e_axis`` multiplies in as ``q cos + (q e_axis) sin``,
    where ``q e_axis`` is a signed permutation of q's components: the products of
    :func:`qmul` without its zeros, one component array at a time."""
    q: list[np.ndarray | None] = [None, None, None, cos[0]]  # x, y, z, w; None is zero
    q["XYZ".index(order[0])] = sin[0]
    for i, axis in enumerate(order[1:], start=1):
        perm, sign = _TIMES_AXIS[axis]
        s, c, minus_s = sin[i], cos[i], -sin[i]
        new: list[np.ndarray | None] = []
        for k in range(4):
            a, b = q[k], q[perm[k]]
            bs = None if b is None else b * (s if sign[k] > 0 else minus_s)
            new.append(bs if a is None else a * c if bs is None else a * c + bs)
        q = new
    return [0.0 if part is None else part for part in q]


def to_euler(q: np.ndarray, order: str, degrees: bool = True) -> np.ndarray:
    """Quaternions to intrinsic Euler angles in ``order``. q : (..., 4) -> (..., 3)."""
    def fn(x: np.ndarray) -> np.ndarray:
        with warnings.catch_warnings():  # gimbal lock: scipy warns and picks a valid solution
            warnings.simplefilter("ignore", UserWarning)
            return _transform().Rotation.from_quat(x).as_euler(order.upper(), degrees=degrees)
    return _apply(fn, q, 1)


def to_matrix(q: np.ndarray) -> np.ndarray:
    """q : (..., 4) -> rotation matrices (..., 3, 3)."""
    return _apply(lambda x: _transform().Rotation.from_quat(x).as_matrix(), q, 1)


@functools.cache
def _skip_orthogonalization() -> dict[str, bool]:
    """``Rotation.from_matrix``'s keyword that skips its orthogonalization where this SciPy
    has it (1.17+), else none."""
    try:
        signature = inspect.signature(_transform().Rotation.from_matrix)
        takes = "assume_valid" in signature.parameters
    except (TypeError, ValueError):  # a compiled method without a signature: older SciPy
        takes = False
    return {"assume_valid": True} if takes else {}


def from_matrix(m: np.ndarray, orthonormal: bool = False) -> np.ndarray:
    """Rotation matrices (..., 3, 3) -> q (..., 4).

    ``orthonormal``: the matrices are rotations already (orthonormal, determinant 1), so SciPy
    may skip the SVD that finds the nearest rotation (where SciPy offers it: 1.17+): half
    the time of :func:`from_6d` on a pose's 23 joints (0.30 -> 0.15 ms, idle machine)."""
    kw = _skip_orthogonalization() if orthonormal else {}
    return _apply(lambda x: _transform().Rotation.from_matrix(x, **kw).as_quat(), m, 2)


def to_rotvec(q: np.ndarray) -> np.ndarray:
    """q : (..., 4) -> axis-angle vectors (..., 3), radians."""
    return _apply(lambda x: _transform().Rotation.from_quat(x).as_rotvec(), q, 1)


def from_rotvec(r: np.ndarray) -> np.ndarray:
    """Axis-angle vectors (..., 3), radians -> q (..., 4)."""
    return _apply(lambda x: _transform().Rotation.from_rotvec(x).as_quat(), r, 1)


def to_6d(q: np.ndarray) -> np.ndarray:
    """The continuous 6-D representation (Zhou et al. 2019): the first two columns of the
    rotation matrix, concatenated. q : (..., 4) -> (..., 6)."""
    m = to_matrix(q)
    return np.concatenate([m[..., :, 0], m[..., :, 1]], axis=-1)


def from_6d(d: np.ndarray) -> np.ndarray:
    """6-D representation (..., 6) -> q (..., 4), by Gram-Schmidt orthogonalisation."""
    return from_matrix(matrices_from_6d(d), orthonormal=True)


def matrices_from_6d(d: np.ndarray) -> np.ndarray:
    """6-D representation (..., 6) -> rotation matrices (..., 3, 3), by Gram-Schmidt
    orthogonalisation (the columns: the first half normalized, the second half made
    orthogonal to it and normalized, their cross product)."""
    d = np.asarray(d, dtype=np.float64)
    a = d[..., :3] / np.linalg.norm(d[..., :3], axis=-1, keepdims=True)
    b = d[..., 3:] - np.sum(a * d[..., 3:], axis=-1, keepdims=True) * a
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    return np.stack([a, b, cross(a, b)], axis=-1)


def about_y(theta: np.ndarray) -> np.ndarray:
    """Rotations by ``theta`` radians about the vertical (+Y) axis. theta : (...) -> (..., 4)."""
    theta = np.asarray(theta, dtype=np.float64)
    z = np.zeros_like(theta)
    return np.stack([z, np.sin(theta / 2), z, np.cos(theta / 2)], axis=-1)


def slerp_toward(q: np.ndarray, target: np.ndarray, w: np.ndarray | float) -> np.ndarray:
    """Quaternions ``q`` (..., 4) slerped toward ``target`` (..., 4) by ``w`` (...) or a scalar
    (0: ``q``, 1: ``target``): ``q exp(w log(q^-1 target))``. Written out because scipy's
    ``Slerp`` interpolates one key-framed track, not pairs with a weight each."""
    step = to_rotvec(qmul(qinv(q), target))
    return normalize(qmul(q, from_rotvec(np.asarray(w, dtype=np.float64)[..., None] * step)))


def slerp(q: np.ndarray, times: np.ndarray, new_times: np.ndarray) -> np.ndarray:
    """Spherical linear interpolation of a time series. q : (T, ..., 4) sampled at ``times``
    (T,) -> (len(new_times), ..., 4). Each trailing track is interpolated independently."""
    q = np.asarray(q, dtype=np.float64)
    t, rest = q.shape[0], q.shape[1:-1]
    flat = q.reshape(t, -1, 4)
    rotation, slerp_ = _transform().Rotation, _transform().Slerp
    out = np.stack([slerp_(times, rotation.from_quat(flat[:, k]))(new_times).as_quat()
                    for k in range(flat.shape[1])], axis=1)
    return out.reshape((len(new_times),) + rest + (4,))
