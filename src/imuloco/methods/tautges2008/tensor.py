"""Motion tensors of Tautges et al. 2008 (sec. 2.2-2.3): registered gait cycles, N-mode SVD
and synthesis by linear combinations of natural-mode rows.

A *cycle* is one gait cycle (right foot strike to the next, found by :mod:`imuloco.phases`),
time-registered by a linear warp to ``F + 1`` samples (the last sample is the next cycle's
first, so that cycles can be chained) and put in a canonical frame: heading 0 and the root over
the origin at its first sample.

Tensors (the shared data has content and style labels but no actor, so the natural modes are
style x repetition; one tensor per content, i.e. per motion type):

- rotations ``(4, J, F + 1, styles, repetitions)``: DOF (quaternion x, y, z, w) x joint x frame;
- root translation ``(3, F + 1, styles, repetitions)``: the root's position, a separate tensor
  because its range differs from that of unit quaternions (sec. 2.2).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
import tensorly as tl
from tensorly.decomposition import tucker
from tensorly.tenalg import multi_mode_dot

from imuloco.core.motion import Motion
from imuloco.methods.pose import heading
from imuloco.ops.rotations import (
    about_y,
    continuous,
    from_rotvec,
    normalize,
    qinv,
    qmul,
    qrot,
    slerp,
    to_rotvec,
)
from imuloco.phases import gait_phases


def gait_cycles(motion: Motion) -> list[tuple[int, int]]:
    """``(start, stop)`` frames of complete gait cycles, right strike to next right strike
    (``stop`` is the next cycle's first frame)."""
    strikes = gait_phases(motion).steps["right"]
    return [(int(a), int(b)) for a, b in itertools.pairwise(strikes) if b - a >= 4]


def register_cycle(motion: Motion, start: int, stop: int, frames: int
                   ) -> tuple[np.ndarray, np.ndarray]:
    """One cycle warped linearly to ``frames + 1`` samples, in the canonical frame.

    Returns
    -------
    rotations : ndarray, shape (frames + 1, J, 4), local, root yaw 0 at sample 0.
    root : ndarray, shape (frames + 1, 3), metres, horizontal origin at sample 0.
    """
    t = np.arange(start, stop + 1) / motion.fps
    new_t = np.linspace(t[0], t[-1], frames + 1)
    rot = slerp(motion.rotations[start:stop + 1], t, new_t)
    root = np.stack([np.interp(new_t, t, motion.root[start:stop + 1, k]) for k in range(3)], 1)
    yaw = qinv(about_y(heading(motion.slice(start, start + 1))[0]))
    rot[:, 0] = qmul(yaw, rot[:, 0])
    root = root - root[0] * np.array([1.0, 0.0, 1.0])
    rot, root = continuous(rot, axis=0), qrot(yaw, root)
    # Loop closure: a recorded cycle's last pose differs a little from its first, and chained
    # cycles (chain_cycles) would jump there; spread the mismatch linearly over the cycle.
    target = rot[0].copy()
    target[0] = qmul(about_y(cycle_turn(rot)), rot[0, 0])
    delta = to_rotvec(qmul(rot[-1], qinv(target)))                        # (J, 3)
    frac = np.linspace(0.0, 1.0, frames + 1)[:, None, None]
    rot = qmul(from_rotvec(-frac * delta), rot)
    root[:, 1] -= frac[:, 0, 0] * (root[-1, 1] - root[0, 1])
    return continuous(rot, axis=0), root


def cycle_turn(rotations: np.ndarray) -> np.ndarray:
    """Heading change over a cycle, from the root joint's rotation of the first and last
    samples. rotations : (..., F + 1, J, 4) -> (...) radians."""
    fwd = np.array([0.0, 0.0, 1.0])
    f_a, f_b = qrot(rotations[..., 0, 0, :], fwd), qrot(rotations[..., -1, 0, :], fwd)
    return np.arctan2(f_b[..., 0], f_b[..., 2]) - np.arctan2(f_a[..., 0], f_a[..., 2])


def align_signs(rotations: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Flip whole quaternion tracks to the reference's hemisphere, so that linear combinations
    of cycles (eq. 3) interpolate rather than cancel.
    rotations : (N, F, J, 4), reference : (J, 4) -> (N, F, J, 4)."""
    sign = np.sign(np.sum(rotations[:, :1] * reference, axis=-1, keepdims=True))
    return rotations * np.where(sign == 0, 1.0, sign)


@dataclass
class MotionModel:
    """A decomposed motion tensor pair, ready for synthesis (eq. 3-4).

    Attributes
    ----------
    rot_basis : ndarray, shape (4, J, F + 1, r_s, r_r): the rotation core tensor multiplied
        by the technical-mode matrices, ``Phi x1 U1 x2 U2 x3 U3``.
    root_basis : ndarray, shape (3, F + 1, p_s, p_r): the same for the root tensor.
    rot_natural : [U_style (d_s, r_s), U_rep (d_r, r_r)] of the rotation tensor.
    root_natural : [U_style (d_s, p_s), U_rep (d_r, p_r)] of the root tensor.
    period : ndarray, shape (d_s, d_r): each cycle's duration, frames at the clip rate.
    """

    rot_basis: np.ndarray
    root_basis: np.ndarray
    rot_natural: list[np.ndarray]
    root_natural: list[np.ndarray]
    period: np.ndarray

    @property
    def x_mean(self) -> list[np.ndarray]:
        """x of eq. 4 for uniform weights lambda = 1/d (the mean motion)."""
        return [u.mean(axis=0) for u in self.rot_natural]

    def to_lambda(self, x: list[np.ndarray]) -> list[np.ndarray]:
        """lambda of eq. 4 from x = lambda U (least-norm: lambda = x U^T, U has orthonormal
        columns)."""
        return [xi @ u.T for xi, u in zip(x, self.rot_natural)]

    def synthesize(self, x_style: np.ndarray, x_rep: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
        """One registered cycle from eq. 3 with ``x = lambda U`` (eq. 4).

        x_style : (..., r_s), x_rep : (..., r_r) -> rotations (..., F + 1, J, 4) unit
        quaternions, root (..., F + 1, 3). The root tensor gets the same lambda.
        """
        q = np.einsum("djfsr,...s,...r->...fjd", self.rot_basis, x_style, x_rep)
        lam_s = x_style @ self.rot_natural[0].T
        lam_r = x_rep @ self.rot_natural[1].T
        p = np.einsum("dfsr,...s,...r->...fd", self.root_basis,
                      lam_s @ self.root_natural[0], lam_r @ self.root_natural[1])
        return normalize(q), p

    def arrays(self, prefix: str) -> dict[str, np.ndarray]:
        """The model as named arrays for a model file."""
        return {f"{prefix}rot_basis": self.rot_basis, f"{prefix}root_basis": self.root_basis,
                f"{prefix}rot_us": self.rot_natural[0], f"{prefix}rot_ur": self.rot_natural[1],
                f"{prefix}root_us": self.root_natural[0],
                f"{prefix}root_ur": self.root_natural[1], f"{prefix}period": self.period}

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray], prefix: str) -> MotionModel:
        a = {k[len(prefix):]: arrays[k] for k in arrays if k.startswith(prefix)}
        return cls(a["rot_basis"], a["root_basis"], [a["rot_us"], a["rot_ur"]],
                   [a["root_us"], a["root_ur"]], a["period"])


def hosvd(tensor: np.ndarray, ranks: list[int]) -> tuple[np.ndarray, list[np.ndarray]]:
    """N-mode SVD (eq. 1) truncated to ``ranks`` (one per mode): core and factor matrices
    ``U_k`` (d_k, r_k) with orthonormal columns. Without truncation the product of eq. 1
    gives the tensor back exactly. Uses tensorly's Tucker decomposition (SVD initialisation,
    refined by HOOI iterations when truncated)."""
    size = int(np.prod(tensor.shape))
    # a mode's rank cannot exceed the other modes' product (the unfolding's width)
    ranks = [min(r, d, size // d) for r, d in zip(ranks, tensor.shape)]
    full = all(r == min(d, size // d) for r, d in zip(ranks, tensor.shape))
    core, factors = tucker(tl.tensor(tensor), rank=list(ranks), init="svd",
                           n_iter_max=0 if full else 100, tol=1e-8)
    return np.asarray(core), [np.asarray(f) for f in factors]


def build_model(cycles_rot: np.ndarray, cycles_root: np.ndarray, period: np.ndarray,
                style_rank: int | None = None, repetition_rank: int | None = None
                ) -> MotionModel:
    """Decompose the motion tensors of one motion type.

    Parameters
    ----------
    cycles_rot : ndarray, shape (d_s, d_r, F + 1, J, 4), registered cycles per style and
        repetition, quaternion signs aligned.
    cycles_root : ndarray, shape (d_s, d_r, F + 1, 3).
    period : ndarray, shape (d_s, d_r), cycle durations in frames.
    style_rank, repetition_rank : truncation of the natural modes (``None``: keep all).
    """
    ds, dr = cycles_rot.shape[:2]
    rs = min(style_rank or ds, ds)
    rr = min(repetition_rank or dr, dr)
    theta_q = np.transpose(cycles_rot, (4, 3, 2, 0, 1))  # DOF x joint x frame x style x rep
    theta_p = np.transpose(cycles_root, (3, 2, 0, 1))    # DOF x frame x style x rep
    core_q, uq = hosvd(theta_q, list(theta_q.shape[:3]) + [rs, rr])
    core_p, up = hosvd(theta_p, list(theta_p.shape))
    rot_basis = multi_mode_dot(core_q, uq[:3], modes=[0, 1, 2])
    root_basis = multi_mode_dot(core_p, up[:2], modes=[0, 1])
    return MotionModel(rot_basis, root_basis, uq[3:], up[2:], np.asarray(period, float))


def chain_cycles(rotations: np.ndarray, root: np.ndarray, u: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Sample a registered cycle repeated end to end at cycle times ``u`` (>= 0; 1 is one
    cycle): each repetition starts where the previous ended, turned by the cycle's own
    change of heading.

    rotations : (..., F + 1, J, 4), root : (..., F + 1, 3), u : (..., N)
    -> rotations (..., N, J, 4), root (..., N, 3).
    """
    f1 = rotations.shape[-3]
    k = np.floor(u).astype(int)
    s = (u - k) * (f1 - 1)
    i0 = np.clip(np.floor(s).astype(int), 0, f1 - 2)
    w = (s - i0)[..., None]
    take = lambda a, i: np.take_along_axis(a, i.reshape(i.shape + (1,) * (a.ndim - i.ndim)),
                                           axis=i.ndim - 1)
    q0, q1 = take(rotations, i0), take(rotations, i0 + 1)
    q1 = q1 * np.sign(np.sum(q0 * q1, axis=-1, keepdims=True) + 1e-12)
    q = normalize(q0 * (1 - w[..., None]) + q1 * w[..., None])
    p = take(root, i0) * (1 - w) + take(root, i0 + 1) * w
    # heading change and horizontal displacement of one cycle, from the root joint
    dpsi = cycle_turn(rotations)
    step = root[..., -1, :] * np.array([1.0, 0.0, 1.0])
    out_q, out_p = q.copy(), p.copy()
    for n in range(1, int(k.max(initial=0)) + 1):  # a window spans a few cycles at most
        yaw = about_y(n * dpsi)[..., None, :]
        # displacement after n cycles: sum of the step turned by 0, dpsi, ..., (n-1) dpsi
        off = sum(qrot(about_y(m * dpsi), step) for m in range(n))
        sel = (k == n)[..., None]
        turned = q.copy()
        turned[..., 0, :] = qmul(yaw, q[..., 0, :])  # only the root's rotation is global
        out_q = np.where(sel[..., None], turned, out_q)
        out_p = np.where(sel, qrot(yaw, p) + off[..., None, :], out_p)
    return out_q, out_p
