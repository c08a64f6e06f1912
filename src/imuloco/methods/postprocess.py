"""Post-processing shared by the methods: feet pinned during contact (offline and online),
Laplacian smoothing, a centred Gaussian window over frames (offline and online)."""

from __future__ import annotations

import sys
from importlib.util import find_spec

import numpy as np
from scipy.signal import lfilter
from scipy.signal.windows import gaussian

from imuloco.core.motion import Motion
from imuloco.core.skeleton import Skeleton
from imuloco.ops.ik import two_bone
from imuloco.ops.kinematics import fk
from imuloco.ops.rotations import (
    continuous,
    cross,
    from_rotvec,
    normalize,
    qinv,
    qmul,
    qrot,
    to_rotvec,
)
from imuloco.phases.contacts import foot_contacts


def _check_smoothing(smoothing: float) -> None:
    if not 0.0 < smoothing <= 1.0:
        raise ValueError(f"foot pinning: smoothing must be in (0, 1], got {smoothing}")


def pin_detected_contacts(motion: Motion) -> Motion:
    """:func:`pin_feet` on the foot contacts detected on ``motion`` itself
    (:func:`imuloco.phases.foot_contacts`: feet low and slow); motions under two frames are
    returned as they are."""
    if motion.num_frames < 2:
        return motion
    c = foot_contacts(motion)
    return pin_feet(motion, np.stack([c["left_foot"], c["right_foot"]], axis=1))


def pin_feet(motion: Motion, contacts: np.ndarray, feet: tuple[str, ...] = ("left_ankle",
             "right_ankle"), smoothing: float = 1.0) -> Motion:
    """Remove foot skating by moving the root so that feet in contact do not slide.

    Each frame's horizontal root step is replaced by the one that keeps the contact foot's
    world position still (the mean over feet in contact, weighted by contact probability);
    frames with no foot in contact keep their own step. Heights are untouched.

    Parameters
    ----------
    motion : the reconstruction.
    contacts : ndarray, shape (T, len(feet)), contact probabilities or booleans per foot.
    feet : body parts whose contact is given.
    smoothing : in (0, 1]; the correction (pinned step minus own step) goes through a causal
        exponential moving average with this weight per frame: 1 applies each frame's own
        correction; less spreads a contact switch over a few frames, trading a little sliding
        for less jerk (the step from a foot's relative velocity carries the pose's jitter).
    """
    _check_smoothing(smoothing)
    contacts = np.asarray(contacts, dtype=np.float64)
    pos = motion.positions()
    idx = [motion.skeleton.part(f) for f in feet]
    rel = pos[:, idx, :] - motion.root[:, None, :]          # feet relative to the root (T, F, 3)
    step = np.diff(motion.root, axis=0)[:, [0, 2]]            # own horizontal root steps (T-1, 2)
    w = np.minimum(contacts[1:], contacts[:-1])               # in contact at both ends of a step
    pinned = -np.diff(rel, axis=0)[..., [0, 2]]               # root step that keeps a foot still
    wsum = w.sum(axis=1, keepdims=True)
    target = np.where(wsum > 0, (w[..., None] * pinned).sum(1) / np.maximum(wsum, 1e-9), step)
    correction = np.clip(wsum, 0.0, 1.0) * (target - step)
    if smoothing < 1.0 and len(correction):
        correction = lfilter([smoothing], [1.0, smoothing - 1.0], correction, axis=0)
    root = motion.root.copy()
    root[1:, [0, 2]] = motion.root[0, [0, 2]] + np.cumsum(step + correction, axis=0)
    return Motion(motion.skeleton, motion.rotations, root, motion.fps, motion.name)


# FootLock: a held foot's furthest from the motion, in foot lengths (and a flat foot's
# furthest turn, in radians: its toe as far along the arc about the ankle)
MAX_HOLD_FEET = 1.0
LEGS = (("left_hip", "left_knee", "left_ankle", "left_toe"),
        ("right_hip", "right_knee", "right_ankle", "right_toe"))


def lock_feet(motion: Motion, heel: np.ndarray, toe: np.ndarray, smoothing: float = 1.0,
              release_s: float = 0.1, threshold: float = 0.5, hold_flat: bool = True,
              flat_pitch: float | None = None, engine: str = "auto") -> Motion:
    """Keep each planted foot where it landed on the floor by bending its leg (two-bone IK,
    :func:`imuloco.ops.ik.two_bone`), after :func:`pin_feet` has moved the root.

    Moving the root can hold one foot still, not two that drift apart, nor the sliding that
    its smoothing leaves. Causally, frame by frame (:class:`FootLock`, which a stream runs):
    when a heel comes down the ankle is held where it stands; when only the toe is down (the
    heel rising) the toe is held and the ankle follows the foot's own orientation; when the
    foot lifts, the correction fades out with time constant ``release_s``; where the motion
    takes the foot further than its own length (:data:`MAX_HOLD_FEET`) from the held point
    (a pivot, a step the contacts missed), the held point slides along. Only the position
    on the floor is held: the height stays the motion's (holding it too cost accuracy and
    smoothness on unseen contents: ``docs/results/learned/experiments.md``, thirteenth
    round). A foot flat on the floor (heel and toe both down, ``hold_flat``) cannot tilt or
    turn without one of them sliding, so its direction (ankle to toe) is held as well, with
    the same smoothing, fade-out and bound (:data:`MAX_HOLD_FEET` radians: the toe a foot
    length along its arc): the heading it lands with, at ``flat_pitch`` where that is known
    (:func:`imuloco.phases.contacts.flat_foot_pitch` of the motions a model learned from; the
    pitch it lands with is that of a foot still rolling onto the floor). Only the hip, knee
    and ankle joints turn, the foot keeping its orientation (or the held one); a target out of
    the leg's reach is approached as far as the leg stretches.

    Parameters
    ----------
    motion : the reconstruction (world positions after root pinning).
    heel, toe : (T, 2) contact probabilities of the left and right heel (ankle) and toe.
    smoothing : in (0, 1]; the correction goes through a causal exponential moving average
        with this weight per frame, as :func:`pin_feet`'s.
    release_s : time constant of the fade-out after a foot lifts, seconds.
    threshold : a probability above it is a contact.
    hold_flat : hold a flat foot's direction too (False: the foot's orientation is always the
        motion's).
    flat_pitch : radians, the pitch of a foot flat on the floor
        (:func:`imuloco.phases.contacts.flat_foot_pitch`);
        None: a flat foot keeps the pitch it lands with.
    engine : ``numba`` runs the frame loop compiled (:mod:`imuloco.methods.lockcompiled`),
        ``numpy`` as :meth:`FootLock.run` (the same to rounding); ``auto``: numba when
        installed and the motion long enough to pay its loading (:func:`resolve_engine`).
    """
    if motion.num_frames < 2:
        return motion
    lock = FootLock(motion.skeleton, motion.fps, smoothing, release_s, threshold, hold_flat,
                    flat_pitch)
    heel, toe = np.asarray(heel, dtype=np.float64), np.asarray(toe, dtype=np.float64)
    legs = lock.legs(motion.rotations, motion.root)
    feet = legs[1][:, lock.sub_feet]
    if resolve_engine(engine, motion.num_frames) == "numba":
        from imuloco.methods.lockcompiled import lock_targets  # the optional numba extra

        targets, turns = lock_targets(
            np.ascontiguousarray(feet), np.ascontiguousarray(heel), np.ascontiguousarray(toe),
            float(threshold), bool(hold_flat), float(smoothing), lock.decay,
            np.asarray(lock.slip_m, dtype=np.float64),
            np.nan if flat_pitch is None else float(flat_pitch), float(MAX_HOLD_FEET))
    else:
        targets, turns = lock.run(feet, heel, toe)
    rot = lock.bend(motion.rotations, motion.root, targets, legs, turns)
    return Motion(motion.skeleton, rot, motion.root, motion.fps, motion.name)


ENGINES = ("auto", "numba", "numpy")
# ``auto`` compiles from this many frames on: loading numba and the cached kernel costs ~0.4 s
# of CPU and ~100 MB of memory (LLVM) once a process, the numpy loop ~0.1 ms a frame (5 min
# at 30 fps: ~1 s)
NUMBA_FRAMES = 9000


def resolve_engine(engine: str, frames: int = NUMBA_FRAMES) -> str:
    """``auto`` -> ``numba`` when numba is installed (the ``fast`` extra) and either ``frames``
    is at least :data:`NUMBA_FRAMES` or the kernel is already loaded in this process (a batch
    worker pays its loading once), else ``numpy``; checks the name."""
    if engine not in ENGINES:
        raise ValueError(f"engine must be one of {', '.join(ENGINES)}, got {engine!r}")
    if engine == "auto":
        loaded = "imuloco.methods.lockcompiled" in sys.modules
        worth = loaded or frames >= NUMBA_FRAMES
        return "numba" if worth and find_spec("numba") is not None else "numpy"
    return engine


def _rest_distance(skeleton: Skeleton, top: int, joint: int) -> float:
    """Distance in the rest pose from joint ``top`` to ``joint``, one of its descendants
    (metres): the bones' offsets summed up the chain."""
    step = np.zeros(3)
    while joint != top:
        step, joint = step + skeleton.offsets[joint], int(skeleton.parents[joint])
        if joint < 0:
            raise ValueError(f"joint {skeleton.names[top]!r} is no ancestor of the toe")
    return float(np.linalg.norm(step))


def pitched(d: np.ndarray, pitch: float) -> np.ndarray:
    """Directions ``d`` (..., 3) turned up or down to ``pitch`` radians against the horizontal
    (Y up), their heading and length kept; a vertical one, without a heading, is kept."""
    flat = np.linalg.norm(d[..., [0, 2]], axis=-1, keepdims=True)
    length = np.linalg.norm(d, axis=-1, keepdims=True)
    scale = length * np.cos(pitch) / np.maximum(flat, 1e-12)
    out = np.concatenate([d[..., :1] * scale, length * np.sin(pitch), d[..., 2:] * scale],
                         axis=-1)
    return np.where(flat > 1e-9 * np.maximum(length, 1e-12), out, d)


def _quaternion(r: np.ndarray) -> np.ndarray:
    """Rotation vectors (..., 3) -> quaternions (..., 4): the formula, as :func:`_between`
    (:func:`imuloco.ops.rotations.from_rotvec` goes through a scipy Rotation)."""
    angle = np.linalg.norm(r, axis=-1, keepdims=True)
    # sin(a / 2) / a without a division by zero: np.sinc(x) is sin(pi x) / (pi x)
    return np.concatenate([r * 0.5 * np.sinc(angle / (2 * np.pi)), np.cos(angle / 2)], axis=-1)


def _between(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotation vectors (..., 3) of the shortest rotations taking the directions ``u`` to
    ``v`` (..., 3): about their cross product by the angle between them; zero where they are
    parallel or opposite (a foot turned half round in a frame is not held). The formula, not
    :func:`imuloco.ops.ik.arc` and a conversion: a stream runs it every frame (two feet: 50
    against 223 us, both measured on a loaded machine)."""
    axis = cross(u, v)
    sine = np.linalg.norm(axis, axis=-1, keepdims=True)  # |u| |v| sin, and below |u| |v| cos
    angle = np.arctan2(sine, np.sum(u * v, axis=-1, keepdims=True))
    return np.where(sine > 1e-12, axis * (angle / np.maximum(sine, 1e-12)), 0.0)


class FootLock:
    """:func:`lock_feet` one frame at a time (bounded state: per foot the held point and
    direction and the corrections): :meth:`targets` for where the ankles should be (and
    :attr:`turn`, how the feet turn), :meth:`bend` for the legs that put them there. Only the
    legs and their ancestors' kinematics are computed (a stream bends a leg nearly every
    frame)."""

    def __init__(self, skeleton: Skeleton, fps: float, smoothing: float = 1.0,
                 release_s: float = 0.1, threshold: float = 0.5, hold_flat: bool = True,
                 flat_pitch: float | None = None) -> None:
        _check_smoothing(smoothing)
        if not release_s > 0:
            raise ValueError(f"foot locking: release_s must be positive, got {release_s}")
        self.chains = [tuple(skeleton.part(p) for p in leg[:3]) for leg in LEGS]
        # the joints :meth:`targets` reads: the left and right ankle, then toe
        self.feet = [c[2] for c in self.chains] + [skeleton.part(leg[3]) for leg in LEGS]
        parents = skeleton.parents
        need: set[int] = set()
        for j in [*(j for c in self.chains for j in c), *self.feet]:
            while j >= 0 and j not in need:
                need.add(j)
                j = int(parents[j])
        self.joints = sorted(need)  # the legs and their ancestors; parents come first
        at = {j: i for i, j in enumerate(self.joints)}
        self.sub_parents = np.array([at[int(parents[j])] if parents[j] >= 0 else -1
                                     for j in self.joints])
        self.sub_offsets = skeleton.offsets[self.joints]
        self.sub_feet = [at[j] for j in self.feet]
        # per leg, into the joints above: the globals two_bone reads, then its positions
        self.rows = np.array([[at[int(x)] for x in (parents[h], h, parents[k], k, parents[e], e)]
                              for h, k, e in self.chains])
        # a foot is held at most MAX_HOLD_FEET of its own length (ankle to toe) from where
        # the motion puts it: further, the motion has left it, and it slides along
        self.slip_m = [MAX_HOLD_FEET * _rest_distance(skeleton, ankle, toe)
                       for ankle, toe in zip(self.feet[:len(LEGS)], self.feet[len(LEGS):])]
        self.smoothing, self.threshold, self.hold_flat = smoothing, threshold, hold_flat
        self.flat_pitch = flat_pitch
        self.decay = float(np.exp(-1.0 / (release_s * fps)))
        self.held: list[tuple[str, np.ndarray] | None] = [None] * len(LEGS)
        self.offset = np.zeros((len(LEGS), 3))
        self.applied = np.zeros((len(LEGS), 3))
        # a flat foot's held direction (ankle to toe), NaN when not flat; the turns it wants
        # and the turns applied (rotation vectors, world frame); :attr:`turn` as quaternions
        self.direction = np.full((len(LEGS), 3), np.nan)
        self.tilt = np.zeros((len(LEGS), 3))
        self.turned = np.zeros((len(LEGS), 3))
        self.turn = np.tile([0.0, 0.0, 0.0, 1.0], (len(LEGS), 1))

    def _turn(self, feet: np.ndarray, flat: np.ndarray) -> np.ndarray:
        """Update the feet's turns (:attr:`turn`) for one frame: feet (4, 3) as in
        :meth:`targets`, flat (2,) which feet lie flat -> (2, 3) the toes as the turns put
        them."""
        ankles, tips = feet[:len(LEGS)], feet[len(LEGS):]
        if not (flat.any() or self.turned.any()):  # nothing held, nothing fading
            self.direction[:] = np.nan
            return tips
        foot = tips - ankles
        lands = flat & np.isnan(self.direction[:, 0])  # from the direction as it stands
        if lands.any():
            landed = qrot(_quaternion(self.turned[lands]), foot[lands])
            self.direction[lands] = (landed if self.flat_pitch is None else
                                     pitched(landed, self.flat_pitch))
        self.direction[~flat] = np.nan
        self.tilt[~flat] *= self.decay
        if flat.any():
            tilt = _between(foot[flat], self.direction[flat])
            angle = np.linalg.norm(tilt, axis=-1, keepdims=True)
            # the motion turned the foot further than a foot length at the toe: it turns along
            far = angle[:, 0] > MAX_HOLD_FEET
            if far.any():
                tilt[far] *= MAX_HOLD_FEET / angle[far]
                self.direction[np.flatnonzero(flat)[far]] = qrot(_quaternion(tilt[far]),
                                                                 foot[flat][far])
            self.tilt[flat] = tilt
        self.turned += self.smoothing * (self.tilt - self.turned)
        # faded out (under a nanoradian): nothing to turn, and nothing to compute from now on
        self.turned[~flat & (np.abs(self.turned).max(axis=-1) < 1e-9)] = 0.0
        self.turn = _quaternion(self.turned)
        return ankles + qrot(self.turn, foot)

    def targets(self, feet: np.ndarray, heel: np.ndarray, toe: np.ndarray) -> np.ndarray:
        """feet : (4, 3) one frame's positions of the joints :attr:`feet`; heel, toe : (2,)
        contact probabilities -> (2, 3) where each ankle should be; :attr:`turn` (2, 4) then
        holds how each foot turns about its ankle (world frame)."""
        out = np.empty((len(LEGS), 3))
        heel, toe = np.asarray(heel), np.asarray(toe)
        flat = (heel > self.threshold) & (toe > self.threshold) & self.hold_flat
        tips = self._turn(feet, flat)
        for side in range(len(LEGS)):
            ankle, tip = feet[side], tips[side]
            kind = ("heel" if heel[side] > self.threshold else
                    "toe" if toe[side] > self.threshold else None)
            held = self.held[side]
            if kind is None:
                self.held[side] = None
                self.offset[side] *= self.decay
            else:
                point = ankle if kind == "heel" else tip
                if held is None or held[0] != kind:  # lands (or rolls onto its toe) here
                    held = self.held[side] = (kind, point + self.applied[side])
                self.offset[side] = held[1] - point
                self.offset[side, 1] = 0.0  # on the floor only
                far = float(np.linalg.norm(self.offset[side]))
                if far > self.slip_m[side]:  # the motion left the held point: let it slide
                    self.offset[side] *= self.slip_m[side] / far
                    self.held[side] = (kind, point + self.offset[side])
            self.applied[side] += self.smoothing * (self.offset[side] - self.applied[side])
            out[side] = ankle + self.applied[side]
        return out

    def run(self, feet: np.ndarray, heel: np.ndarray, toe: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`targets` and :attr:`turn` for frames one after the other: feet (T, 4, 3),
        heel and toe (T, 2) -> targets (T, 2, 3), turns (T, 2, 4)."""
        targets = np.empty((len(feet), len(LEGS), 3))
        turns = np.empty((len(feet), len(LEGS), 4))
        for t, (f, h, o) in enumerate(zip(feet, heel, toe)):
            targets[t] = self.targets(f, h, o)
            turns[t] = self.turn
        return targets, turns

    def moved(self, feet: np.ndarray, targets: np.ndarray, turns: np.ndarray | None = None
              ) -> np.ndarray:
        """(..., 2) whether each ankle's target differs from where it is (feet (..., 4, 3),
        targets (..., 2, 3)) or its foot turns (turns (..., 2, 4), :attr:`turn`): the legs
        :meth:`bend` changes."""
        out = np.any(np.abs(targets - feet[..., :len(LEGS), :]) > 1e-9, axis=-1)
        if turns is not None:
            out |= np.any(np.abs(turns[..., :3]) > 1e-12, axis=-1)
        return out

    def legs(self, local: np.ndarray, root: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Global rotations and positions (T, K, ...) of :attr:`joints`, the legs and their
        ancestors (the feet among them at :attr:`sub_feet`)."""
        return fk(normalize(local[:, self.joints]), root, self.sub_offsets, self.sub_parents)

    def bend(self, local: np.ndarray, root: np.ndarray, targets: np.ndarray,
             legs: tuple[np.ndarray, np.ndarray] | None = None,
             turns: np.ndarray | None = None) -> np.ndarray:
        """local : (T, J, 4) rotations and root : (T, 3) of frames; targets : (T, 2, 3)
        from :meth:`targets` and turns (T, 2, 4) its :attr:`turn` (None: the feet keep their
        orientation); ``legs``: :meth:`legs` of the same frames when at hand -> the local
        rotations with the legs bent."""
        glob, pos = self.legs(local, root) if legs is None else legs
        local = normalize(local)
        frame, leg = np.nonzero(self.moved(pos[:, self.sub_feet], targets, turns))
        if len(frame):
            rows = self.rows[leg]
            chain = glob[frame[:, None], rows]
            if turns is not None:  # the foot's new orientation: turned about the ankle
                chain[:, 5] = qmul(turns[frame, leg], chain[:, 5])
            new = two_bone(chain, pos[frame[:, None], rows[:, 1::2]], targets[frame, leg])
            local[frame[:, None], np.array(self.chains)[leg]] = new
        return local


class FootPinner:
    """:func:`pin_feet` one frame at a time, for online methods: fed each frame's own root,
    feet relative to it and contacts, it returns the pinned root, the offline result frame for
    frame, with bounded state.

    Parameters
    ----------
    smoothing : as :func:`pin_feet`.
    """

    def __init__(self, smoothing: float = 1.0) -> None:
        _check_smoothing(smoothing)
        self.smoothing = smoothing
        self.prev: tuple | None = None  # own root x, z; feet x, z; contacts (Python floats)
        self.root = np.zeros(3)
        self._xz = (0.0, 0.0)  # self.root's x and z as Python floats
        self.correction = [0.0, 0.0]

    def step(self, raw_root: np.ndarray, rel: np.ndarray, contacts: np.ndarray) -> np.ndarray:
        """raw_root : (3,) the frame's own root; rel : (F, 3) feet minus raw_root (world
        axes); contacts : (F,) -> the pinned root (3,)."""
        # Python floats, not numpy: this runs once per frame inside online methods' hot loops
        # with a few feet, where numpy's per-call overhead dominates (two feet: 23 us a step
        # this way, 38 us with array operations; one tolist per argument, 12 us)
        rx, ry, rz = np.asarray(raw_root, dtype=np.float64).tolist()
        feet = np.asarray(rel, dtype=np.float64).tolist()
        fx, fz = [f[0] for f in feet], [f[2] for f in feet]
        c = np.asarray(contacts, dtype=np.float64).tolist()
        if self.prev is None:
            x, z = rx, rz
        else:
            px, pz, pfx, pfz, pc = self.prev
            sx, sz = rx - px, rz - pz
            w = [min(a, b) for a, b in zip(c, pc)]
            wsum = sum(w)
            if wsum > 0:
                tx = sum(wi * (a - b) for wi, a, b in zip(w, pfx, fx)) / wsum
                tz = sum(wi * (a - b) for wi, a, b in zip(w, pfz, fz)) / wsum
            else:
                tx, tz = sx, sz
            blend = min(max(wsum, 0.0), 1.0)
            a, corr = self.smoothing, self.correction
            corr[0] += a * (blend * (tx - sx) - corr[0])
            corr[1] += a * (blend * (tz - sz) - corr[1])
            x, z = self._xz
            x, z = x + sx + corr[0], z + sz + corr[1]
        self._xz = (x, z)
        self.prev = (rx, rz, fx, fz, c)
        self.root = np.array([x, ry, z])
        return self.root.copy()


def laplacian_smooth_quaternions(q: np.ndarray, lam: float = 0.5, iterations: int = 3
                                 ) -> np.ndarray:
    """Laplacian smoothing of rotation tracks in quaternion space (Eom et al. 2014 sec. 6.2).

    Each iteration moves every inner frame's rotation towards the SLERP midpoint of its two
    neighbours by the fraction ``lam`` (itself a SLERP), ``q_t <- slerp(q_t, mid_t, lam)``;
    the first and last frames stay. Shapes broadcast over trailing tracks.

    Parameters
    ----------
    q : ndarray, shape (T, ..., 4), quaternions x, y, z, w.
    lam : step towards the neighbours' midpoint per iteration, in [0, 1].
    iterations : number of passes.

    Returns
    -------
    ndarray, shape (T, ..., 4), unit quaternions in the hemisphere of the input.
    """
    if not 0.0 <= lam <= 1.0:
        raise ValueError(f"laplacian_smooth_quaternions: lam must be in [0, 1], got {lam}")
    q = continuous(normalize(np.asarray(q, dtype=np.float64)), axis=0)
    if len(q) < 3:
        return q
    for _ in range(iterations):
        # the SLERP midpoint of two unit quaternions in one hemisphere is their normalized sum
        mid = normalize(q[:-2] + q[2:])
        step = to_rotvec(qmul(qinv(q[1:-1]), mid))
        inner = qmul(q[1:-1], from_rotvec(lam * step))
        q = np.concatenate([q[:1], inner, q[-1:]], axis=0)
        q = continuous(q, axis=0)
    return q


def laplacian_smooth(x: np.ndarray, lam: float = 0.5, iterations: int = 3) -> np.ndarray:
    """The Euclidean counterpart of :func:`laplacian_smooth_quaternions`:
    ``x_t <- x_t + lam ((x_{t-1} + x_{t+1}) / 2 - x_t)`` per pass, ends fixed.

    x : ndarray, shape (T, ...). Returns the same shape.
    """
    if not 0.0 <= lam <= 1.0:
        raise ValueError(f"laplacian_smooth: lam must be in [0, 1], got {lam}")
    x = np.array(x, dtype=np.float64)
    for _ in range(iterations if len(x) >= 3 else 0):
        x[1:-1] += lam * (0.5 * (x[:-2] + x[2:]) - x[1:-1])
    return x


def gaussian_weights(sigma: float) -> np.ndarray:
    """A centred Gaussian window of ``sigma`` frames, normalized to sum 1, shape (2 r + 1,)
    over scipy.ndimage's radius ``r = int(3 sigma + 0.5)``; ``[1.]`` for ``sigma`` 0."""
    if not 0.0 <= sigma < np.inf:
        raise ValueError(f"gaussian_weights: sigma must be finite and >= 0, got {sigma}")
    r = int(3.0 * sigma + 0.5)
    w = gaussian(2 * r + 1, sigma) if r else np.ones(1)
    return w / w.sum()


def window_average(x: np.ndarray, weights: np.ndarray, ahead: int) -> np.ndarray:
    """Each frame of ``x`` (T + ``ahead``, ...) replaced by the ``weights``-weighted average of
    the frames around it (``weights`` (2 r + 1,), centred), for its first T frames: the last
    ``ahead`` rows are frames past the end, read only as neighbours (a stream's outputs on
    its held last sample, :class:`imuloco.methods.learned.method.LearnedStream`). Frames
    before the first are the first; frames past the end beyond ``ahead``, the last.

    A stream gives the same from a window of its last 2 r + 1 frames, so the average is a
    product with the window, not scipy.ndimage's filter (its edges differ)."""
    r = len(weights) // 2
    x = np.asarray(x, dtype=np.float64)
    if r == 0:
        return x[: len(x) - ahead].copy()
    if not 0 <= ahead <= r or len(x) <= ahead:
        raise ValueError(f"window_average: {ahead} frames past the end of {len(x)}, "
                         f"radius {r}")
    padded = np.concatenate([np.repeat(x[:1], r, axis=0), x,
                             np.repeat(x[-1:], r - ahead, axis=0)])
    windows = np.lib.stride_tricks.sliding_window_view(padded, 2 * r + 1, axis=0)
    return windows @ weights
