"""The per-part fallback (issue 41): where the sensor says the legs stand still, or the model
does not know the motion and a body part is one the sensor cannot see, that part of the
reconstruction moves toward a neutral pose of the detected activity instead of an invented
one, and the predicted error rises to what the neutral pose is expected to miss.

The rule (:func:`apply_fallback`), per frame:

- **activity**: each sensor's own motion energy over a window of
  :attr:`FallbackRule.window_s` seconds, centred offline, the past one live
  (:class:`FallbackStream`): the standard deviation of the gyro and of the accelerometer
  about their window means, so that a bias does not count. Under ``still_gyro`` rad/s and
  ``still_acc`` m/s^2 the sensor is *still* (weight 1), over ``ramp`` times both it *moves*
  (0), smoothly between (:func:`smoothstep` on the larger of the two ratios). Standing
  gestures read 0.06-0.09 rad/s on a simulated shin phone, walking 2-3.5
  (``docs/results/actions/fallback.md``). The *body* is still where the sensors that observe
  the legs are (every sensor, when none does).
- **novelty**: the method's own score (``learned``: how far the network's features lie from
  its training data's, 1 on familiar motion, :mod:`imuloco.methods.learned.confidence`)
  against the method's own flag threshold
  (:attr:`imuloco.methods.base.Method.novelty_threshold`): 0 up to ``novelty_start`` times
  it, 1 from ``novelty_full`` times it, smoothly between; methods without a novelty score
  give 0.
- **observed parts**: each placement declares which body-part groups
  (:data:`imuloco.core.bodymap.PART_GROUPS`) its sensor sees
  (:attr:`imuloco.sensors.placement.Placement.observes`: a shin its leg, the lower back the
  trunk, a watch its arm); several sensors observe the union. An observed group's weight is
  the still weight of the sensors that observe it (the smallest), an unobserved one's the
  larger of the body's still weight and the novelty weight.
- **the neutral pose** of the frame is the standing pose where the body is still, the
  walking mean pose where it moves, slerped between by its still weight
  (:class:`NeutralPoses`, built from training motion by
  :func:`imuloco.lab.neutral.build_neutral`). Each joint's local rotation is slerped toward
  it by its group's weight (the pelvis's tilt against its heading with the legs'); where the
  body stands still the root stops and does not turn (its horizontal steps and the heading's
  turns scaled by one minus the still weight), its height is the standing pose's over the
  floor and both feet are pinned (:func:`imuloco.methods.postprocess.pin_feet`, contact
  weight the still weight), so no phantom step remains for the gait, the strides and the
  path follower. A leg's weight changes only while its foot is off the ground in the
  method's motion (:meth:`FallbackRule.contacts`, :func:`held_legs`), and where a leg is
  blended the root is pinned on the method's planted feet too: the blend does not drag a
  planted foot (starts and stops between kicks and slashes slid the feet 22-74 cm/s).
- **predicted error**: at least ``sqrt(sum_g w_g S_g)``, with ``S_g`` the neutral pose's
  expected squared error of the joints group ``g`` moves over the frame's joint count, on its
  activity (measured by :func:`imuloco.lab.neutral.build_neutral`); frames where an
  unobserved part is held more than half way toward neutral are flagged unreliable (the pose
  there is a guess).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
from scipy.ndimage import uniform_filter1d

from imuloco.core.bodymap import PART_GROUPS
from imuloco.core.contacts import SPEED_TOL
from imuloco.core.motion import Motion
from imuloco.core.recording import Recording
from imuloco.core.skeleton import Skeleton
from imuloco.errors import ModelFileError
from imuloco.io.atomic import atomic_write
from imuloco.methods.base import Method, Reconstruction
from imuloco.methods.postprocess import FootPinner, pin_feet
from imuloco.methods.training import model_frames
from imuloco.ops.heading import heading_from_hips
from imuloco.ops.kinematics import joint_positions
from imuloco.ops.rotations import (
    about_y,
    normalize,
    qinv,
    qmul,
    qrot,
    slerp_toward,
)
from imuloco.sensors.placement import get_placement

GROUPS = tuple(PART_GROUPS)  # ("legs", "arms", "trunk")
ACTIVITIES = ("still", "moving")
NEUTRAL_FILE = "neutral_poses.npz"  # beside the shipped models (imuloco.data.MODELS_DIR)
FEET = ("left_ankle", "left_toe", "right_ankle", "right_toe")
PINNED = ("left_ankle", "right_ankle")  # the joints pin_feet holds where the body stands


def smoothstep(x: np.ndarray) -> np.ndarray:
    """0 below 0, 1 above 1, ``3 x^2 - 2 x^3`` between (continuous slope)."""
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def joint_groups(skeleton: Skeleton) -> np.ndarray:
    """Group index (into :data:`GROUPS`) of each joint's *rotation*, shape (J,), -1 for the
    root: a joint belongs to the group whose parts lie below it, ``trunk`` where several do
    (the chest carries the arms and the head), its parent's where none does (a hand's
    fingers)."""
    parents, n = skeleton.parents, skeleton.num_joints
    own = np.full(n, -1)
    for g, parts in enumerate(PART_GROUPS.values()):
        for p in parts:
            if p in (skeleton.body_map or {}):  # a part the skeleton maps
                own[skeleton.part(p)] = g
    below: list[set[int]] = [set() for _ in range(n)]
    for j in reversed(range(n)):  # parents come first: children are done before their parent
        if own[j] >= 0:
            below[j].add(int(own[j]))
        if parents[j] >= 0:
            below[int(parents[j])] |= below[j]
    trunk = GROUPS.index("trunk")
    out = np.full(n, -1)
    for j in range(n):
        if parents[j] < 0:
            continue
        groups = below[j]
        out[j] = (trunk if trunk in groups or len(groups) > 1 else next(iter(groups))
                  if groups else out[int(parents[j])])
    return out


def position_groups(skeleton: Skeleton) -> np.ndarray:
    """Group index of each joint's *position* (J,): that of the rotation that carries it (its
    parent's); joints the root carries go with the legs (the pelvis tilts with them), the root
    itself is -1."""
    rot = joint_groups(skeleton)
    legs = GROUPS.index("legs")
    par = skeleton.parents
    return np.array([-1 if par[j] < 0 else (rot[par[j]] if rot[par[j]] >= 0 else legs)
                     for j in range(skeleton.num_joints)])


@dataclass(frozen=True)
class NeutralPoses:
    """Neutral poses per activity (:data:`ACTIVITIES`) and what they are expected to miss.

    names : joint names, shape (J,).
    rotations : ndarray, shape (A, J, 4), local rotations (the root's relative to its heading).
    clearance_m : the lowest foot joint's height over the floor when standing, metres.
    sq_error_m2 : ndarray, shape (A, G), the neutral pose's mean squared joint position error
        over the frames of its activity, summed over the joints group ``g`` moves
        (:func:`position_groups`) and divided by the joint count less the root (so that the
        groups' values add up to the frame's mean squared error), m^2.
    source : where it was built from (data, licence).
    """

    names: tuple[str, ...]
    rotations: np.ndarray
    clearance_m: float
    sq_error_m2: np.ndarray
    source: str = ""

    def on(self, skeleton: Skeleton) -> np.ndarray:
        """The rotations (A, J, 4) on ``skeleton``'s joints, found by name; raises
        :class:`~imuloco.errors.ModelFileError` naming a joint the poses do not have."""
        at = {n: i for i, n in enumerate(self.names)}
        missing = [n for n in skeleton.names if n not in at]
        if missing:
            raise ModelFileError(f"{NEUTRAL_FILE}: the neutral poses have no joint "
                                 f"{missing[0]!r} of the model's skeleton (they have "
                                 f"{list(self.names)})")
        return self.rotations[:, [at[n] for n in skeleton.names]]

    def save(self, path: str | Path) -> Path:
        """Write the arrays to one ``.npz`` (no pickle), atomically."""
        with atomic_write(path, "wb") as f:
            np.savez(f, names=np.array(self.names), rotations=self.rotations,
                     clearance_m=np.array(self.clearance_m), sq_error_m2=self.sq_error_m2,
                     activities=np.array(ACTIVITIES), groups=np.array(GROUPS),
                     source=np.array(self.source))
        return Path(path)

    @classmethod
    def load(cls, path: str | Path | None = None) -> NeutralPoses:
        """Read :meth:`save`'s file (default: the shipped one beside the models)."""
        if path is None:
            from imuloco.data import MODELS_DIR

            path = MODELS_DIR / NEUTRAL_FILE
        try:
            with np.load(path, allow_pickle=False) as z:
                names, rot, clear, sq, source, acts, groups = (
                    tuple(str(n) for n in z["names"]), z["rotations"], float(z["clearance_m"]),
                    z["sq_error_m2"], str(z["source"]), tuple(z["activities"]),
                    tuple(z["groups"]))
        except (OSError, KeyError, ValueError) as e:
            raise ModelFileError(f"{path}: not a neutral-poses file ({e})") from None
        if (acts, groups) != (ACTIVITIES, GROUPS) or rot.shape != (len(acts), len(names), 4) \
                or sq.shape != (len(acts), len(groups)):
            raise ModelFileError(f"{path}: expected the activities {list(ACTIVITIES)} and "
                                 f"groups {list(GROUPS)} with rotations (A, J, 4)")
        return cls(names, rot, clear, sq, source)



@dataclass(frozen=True)
class FallbackRule:
    """The rule's settings (module docstring); the defaults are the ones measured in
    ``docs/results/actions/fallback.md``.

    window_s : seconds of the window the sensor's energy is read over (centred offline, the
        past ``window_s`` live).
    still_gyro, still_acc : rad/s and m/s^2 under which the sensor is still (the standard
        deviations of the gyro's and the accelerometer's 3 axes together over the window).
    ramp : over ``ramp`` times those the sensor moves (weight 0).
    novelty_start, novelty_full : the method's novelty score, in units of the method's own
        flag threshold (:attr:`imuloco.methods.base.Method.novelty_threshold`: the 99 %
        quantile of held-out training-motion novelty for ``learned``, 3.62 for the shipped
        shin model), at which an unobserved part starts to move toward neutral and at which
        it is there (at 1.5 and 3.0 in the shin model's units the arms of runs and dashes,
        motion the model knows but whose novelty reads 2-4, fell to the walking pose: dash
        3.9 -> 8.0 cm MPJPE).
    flag_weight : frames where an unobserved part's weight is over this are flagged.
    contact_speed, contact_height : a foot of the method's motion is on the ground where its
        ankle moved slower than ``contact_speed`` leg lengths per second since the last frame
        and is within ``contact_height`` leg lengths of the lower ankle (:meth:`contacts`).
    """

    window_s: float = 1.0
    still_gyro: float = 0.3
    still_acc: float = 1.0
    ramp: float = 2.5
    novelty_start: float = 1.0
    novelty_full: float = 1.5
    flag_weight: float = 0.5
    contact_speed: float = SPEED_TOL
    contact_height: float = 0.03

    def frames(self, fps: float) -> int:
        """The window's length in frames at ``fps`` (odd, at least 1)."""
        return max(1, round(self.window_s * fps) | 1)

    def still_of(self, var: np.ndarray) -> np.ndarray:
        """Still weight (...,) in [0, 1] from the window's variances (..., 2) of the
        accelerometer and of the gyro (each summed over its 3 axes); NaN reads as moving."""
        std = np.sqrt(np.maximum(var, 0.0))
        level = np.maximum(std[..., 1] / self.still_gyro, std[..., 0] / self.still_acc)
        out = 1.0 - smoothstep((level - 1.0) / (self.ramp - 1.0))
        return np.where(np.isfinite(out), out, 0.0)

    def still(self, signals: np.ndarray, fps: float, sensor: int = 0, causal: bool = False
              ) -> np.ndarray:
        """Still weight (T,) in [0, 1] of sensor ``sensor`` of ``signals`` (T, 6 S) at
        ``fps``: 1 still, 0 moving (NaN rows, a gap, read as moving). ``causal``: over the
        past window (the first frame repeated before it), as :class:`FallbackStream` reads
        it live; else a centred one."""
        s = np.asarray(signals, dtype=np.float64)[:, 6 * sensor:6 * sensor + 6]
        if not len(s):
            return np.zeros(0)
        w = self.frames(fps)
        origin = w // 2 if causal else 0  # scipy's origin w // 2: the window ends at the frame
        mean = uniform_filter1d(s, w, axis=0, mode="nearest", origin=origin)
        var = uniform_filter1d(s * s, w, axis=0, mode="nearest", origin=origin) - mean * mean
        return self.still_of(np.stack([var[:, :3].sum(1), var[:, 3:].sum(1)], 1))

    def contacts(self, feet: np.ndarray, fps: float, leg_m: float,
                 before: np.ndarray | None = None) -> np.ndarray:
        """Which of the two feet are on the ground (T, 2), bool, from the ankles' world
        positions (T, 2, 3) at ``fps`` (``before``: the frame before, (2, 3); none: the first
        frame's feet have not moved). Causal and floor-free, unlike
        :func:`imuloco.core.contacts.foot_contacts` (a centred speed, the clip's floor): the
        live mode reads it a frame at a time."""
        feet = np.asarray(feet, dtype=np.float64)
        prev = np.concatenate([feet[:1] if before is None else np.asarray(before)[None],
                               feet[:-1]])
        slow = np.linalg.norm(feet - prev, axis=-1) * fps < self.contact_speed * leg_m
        low = feet[..., 1] - feet[..., 1].min(-1, keepdims=True) < self.contact_height * leg_m
        return slow & low

    def novel(self, novelty: np.ndarray | None, frames: int, threshold: float | None
              ) -> np.ndarray:
        """Novelty weight (T,) in [0, 1] from a method's novelty score on its own scale:
        0 up to ``novelty_start`` times its flag ``threshold``, 1 from ``novelty_full``
        times it. A method without a score or without a threshold gives zeros."""
        if novelty is None or threshold is None or not np.isfinite(threshold) \
                or threshold <= 0:
            return np.zeros(frames)
        x = (np.asarray(novelty, float) / threshold - self.novelty_start) / (
            self.novelty_full - self.novelty_start)
        return np.where(np.isfinite(x), smoothstep(x), 0.0)


@dataclass
class FallbackReport:
    """What the fallback did to a reconstruction (the report's ``fallback``).

    enabled : whether it ran (``--no-fallback`` turns it off).
    weights : ndarray, shape (T, G), each group's weight toward neutral per frame, or None.
    still : ndarray, shape (T,), the sensor's still weight, or None.
    observes : the groups the placement observes.
    note : one sentence for reports.
    """

    enabled: bool
    weights: np.ndarray | None = None
    still: np.ndarray | None = None
    observes: tuple[str, ...] = ()
    note: str = ""
    acted_weight: float = field(default=0.1, repr=False)

    def sliced(self, start: int, stop: int) -> FallbackReport:
        """Frames ``start:stop`` (a piece of a reconstruction in pieces)."""
        def cut(a):
            return None if a is None else a[start:stop]

        return replace(self, weights=cut(self.weights), still=cut(self.still))

    @classmethod
    def concatenate(cls, parts: Sequence[FallbackReport]) -> FallbackReport:
        """Consecutive pieces' reports as one (the first's when any piece has no weights: a
        fallback switched off or not applied says so for every piece)."""
        if any(p.weights is None for p in parts):
            return parts[0]
        return replace(parts[0], weights=np.concatenate([p.weights for p in parts]),
                       still=np.concatenate([p.still for p in parts]))

    @property
    def acted(self) -> bool:
        """Whether some part of some frame moved toward neutral (weight over 0.1)."""
        return self.weights is not None and bool((self.weights > self.acted_weight).any())

    def to_json(self) -> dict[str, Any]:
        """``enabled``, ``acted``, ``still_fraction`` (share of frames the sensor is still),
        ``observes``, per group ``frames_fraction`` (share of frames moved toward neutral,
        weight over 0.1) and ``mean_weight``, and ``note``."""
        out: dict[str, Any] = {"enabled": self.enabled, "acted": self.acted,
                               "still_fraction": None, "observes": list(self.observes),
                               "frames_fraction": None, "mean_weight": None, "note": self.note}
        if self.weights is not None and len(self.weights):
            out["still_fraction"] = round(float((self.still > 0.5).mean()), 4)
            out["frames_fraction"] = {g: round(float((self.weights[:, i] > self.acted_weight)
                                                     .mean()), 4) for i, g in enumerate(GROUPS)}
            out["mean_weight"] = {g: round(float(self.weights[:, i].mean()), 4)
                                  for i, g in enumerate(GROUPS)}
        return out




def observers(placements: Sequence[str]) -> dict[str, list[int]]:
    """For each group (:data:`GROUPS`), the indices of the ``placements`` whose sensor
    observes it (:attr:`~imuloco.sensors.placement.Placement.observes`)."""
    seen = [get_placement(p).observes for p in placements]
    return {g: [i for i, o in enumerate(seen) if g in o] for g in GROUPS}


def group_weights(still: np.ndarray, novel: np.ndarray, placements: Sequence[str]
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Each group's weight toward neutral (T, G) and the body's still weight (T,), from the
    sensors' still weights (T, S) of ``placements`` and the novelty weight (T,).

    The body stands where the sensors that observe the legs are still (all of them; every
    sensor when none observes the legs). A group some sensor observes takes the smallest
    still weight of those that observe it (a shin and a watch: the legs the shin's, the arms
    the watch's); a group none observes the larger of the body's still weight and the
    novelty weight. One sensor: the still weight for its observed groups, the larger of it
    and the novelty weight for the others."""
    still = np.asarray(still, float).reshape(len(novel), -1)
    seen = observers(list(placements))
    body = still[:, seen["legs"] or slice(None)].min(axis=1)
    weights = np.stack([still[:, seen[g]].min(axis=1) if seen[g] else np.maximum(body, novel)
                        for g in GROUPS], axis=1)
    return weights, body


class _Blender:
    """What :func:`blend_motion` and :class:`FallbackStream` do to a pose, frame by frame or
    a clip at once: the shared steps of the rule on one skeleton."""

    def __init__(self, skeleton: Skeleton, neutral: NeutralPoses) -> None:
        self.skeleton = skeleton
        self.target = neutral.on(skeleton)  # (A, J, 4); ModelFileError: a joint missing
        self.clearance_m = neutral.clearance_m
        rot_groups = joint_groups(skeleton)
        self.columns = np.where(rot_groups >= 0, rot_groups, GROUPS.index("legs"))  # root: legs
        self.hips = [skeleton.part("left_hip"), skeleton.part("right_hip")]
        self.feet = [skeleton.part(p) for p in FEET]
        self.pinned = [skeleton.part(p) for p in PINNED]
        self.leg_m = skeleton.leg_length()
        self.sides = [np.flatnonzero(_below(skeleton, skeleton.part(h)))
                      for h in ("left_hip", "right_hip")]

    def heading(self, rot: np.ndarray) -> np.ndarray:
        """The heading (...) of poses' local rotations (..., J, 4), radians (from the hips,
        as :func:`imuloco.methods.pose.heading`)."""
        sk = self.skeleton
        hips = joint_positions(rot, np.zeros(rot.shape[:-2] + (3,)), sk.offsets, sk.parents,
                               self.hips)
        return heading_from_hips(hips[..., 0, :], hips[..., 1, :])

    def pose(self, rot: np.ndarray, weights: np.ndarray, body: np.ndarray,
             heading: np.ndarray, turn: np.ndarray, legs: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray]:
        """Local rotations (..., J, 4) slerped toward the neutral pose of the activity by
        their groups' weights (..., G), each leg's by its own weight ``legs`` (..., 2) (left,
        right; the root's tilt against its ``heading`` (...) by the smaller), the neutral pose
        the standing one by the body's still weight (...), and turned by ``turn`` (...)
        radians about the vertical (the turns the model made while the body stood, taken
        back). Returns them and the lowest foot joint's height (...) over the root."""
        sk, rot = self.skeleton, normalize(rot)
        wj = np.asarray(weights)[..., self.columns].copy()  # (..., J)
        legs = np.asarray(legs)
        for k, joints in enumerate(self.sides):
            wj[..., joints] = legs[..., k:k + 1]
        wj[..., 0] = legs.min(axis=-1)
        if not wj.any() and not np.any(turn):  # nothing to blend (a walk): the method's pose
            feet = joint_positions(rot, np.zeros(rot.shape[:-2] + (3,)), sk.offsets,
                                   sk.parents, self.feet)
            return rot, feet[..., 1].min(axis=-1)
        body = np.asarray(body)
        if np.all(body == 1) or np.all(body == 0):  # standing, or moving, throughout
            target = np.broadcast_to(self.target[0 if body.all() else 1], rot.shape)
        else:
            target = slerp_toward(np.broadcast_to(self.target[1], rot.shape),
                                  np.broadcast_to(self.target[0], rot.shape),
                                  np.broadcast_to(body[..., None], rot.shape[:-1]))
        yaw = about_y(heading)
        out = rot.copy()
        tilt = qmul(qinv(yaw), rot[..., 0, :])
        out[..., 0, :] = qmul(about_y(heading + turn),
                              slerp_toward(tilt, target[..., 0, :], wj[..., 0]))
        out[..., 1:, :] = slerp_toward(rot[..., 1:, :], target[..., 1:, :], wj[..., 1:])
        feet = joint_positions(out, np.zeros(rot.shape[:-2] + (3,)), sk.offsets, sk.parents,
                               self.feet)
        return out, feet[..., 1].min(axis=-1)

    def height(self, root_y: np.ndarray, feet_y: np.ndarray, body: np.ndarray) -> np.ndarray:
        """The root's height (...): the standing pose's over the floor by the body's still
        weight, the method's elsewhere."""
        return (1.0 - body) * root_y + body * (self.clearance_m - feet_y)


def _below(skeleton: Skeleton, top: int) -> np.ndarray:
    """Joints (J,) bool: ``top`` and every joint under it."""
    out = np.zeros(skeleton.num_joints, bool)
    out[top] = True
    for j in range(top + 1, skeleton.num_joints):  # parents come first
        out[j] = skeleton.parents[j] >= 0 and out[skeleton.parents[j]]
    return out


def held_legs(legs: np.ndarray, contacts: np.ndarray, start: np.ndarray | None = None
              ) -> np.ndarray:
    """Each leg's weight toward neutral (T, 2) from the legs group's (T,) held while its
    foot is on the ground (``contacts`` (T, 2)): it changes only while the foot is in the
    air, so that a planted foot is not dragged by the blend of its leg (a start or a stop
    between kicks slid the feet 22-74 cm/s there). ``start`` (2,): the weights before the
    first frame (default: the first frame's)."""
    legs, contacts = np.asarray(legs, float), np.asarray(contacts, bool)
    free = np.where(~contacts, np.arange(len(legs))[:, None], -1)
    last = np.maximum.accumulate(free, axis=0)  # the last frame each foot was in the air
    start = np.full(2, legs[0] if len(legs) else 0.0) if start is None else start
    return np.where(last >= 0, legs[np.maximum(last, 0)], start)


def blend_motion(motion: Motion, weights: np.ndarray, body: np.ndarray,
                 neutral: NeutralPoses, rule: FallbackRule | None = None) -> Motion:
    """``motion`` moved toward the neutral poses per group (module docstring).

    weights : (T, G) per group; body : (T,) the body's still weight (:func:`group_weights`);
    neutral : the neutral poses (their joints found on the motion's skeleton by name);
    rule : the rule (its foot contacts)."""
    rule = FallbackRule() if rule is None else rule
    n = motion.num_frames
    if n == 0:
        return motion
    blender = _Blender(motion.skeleton, neutral)
    ankles = motion.positions()[:, blender.pinned]
    contacts = rule.contacts(ankles, motion.fps, blender.leg_m)
    legs = held_legs(weights[:, GROUPS.index("legs")], contacts)
    heading = np.unwrap(blender.heading(normalize(motion.rotations)))
    # where the body stands it does not turn either: the model's turns there are taken back,
    # from then on (the root's steps with them)
    turn = np.concatenate([[0.0], -np.cumsum(body[1:] * np.diff(heading))])
    rot, feet_y = blender.pose(motion.rotations, weights, body, heading, turn, legs)
    root = motion.root.copy()
    steps = np.zeros((n - 1, 3))
    steps[:, [0, 2]] = np.diff(motion.root[:, [0, 2]], axis=0) * (1.0 - body[1:, None])
    steps = qrot(about_y(turn[1:]), steps)
    root[1:, [0, 2]] = motion.root[0, [0, 2]] + np.cumsum(steps[:, [0, 2]], axis=0)
    root[:, 1] = blender.height(motion.root[:, 1], feet_y, body)
    out = Motion(motion.skeleton, rot, root, motion.fps, motion.name)
    pin = _pinned(contacts, legs, body)
    if n < 2 or not pin.any():
        return out
    return pin_feet(out, pin, PINNED)


def _pinned(contacts: np.ndarray, legs: np.ndarray, body: np.ndarray) -> np.ndarray:
    """The contact weights (..., 2) the root is pinned on: where the body stands both feet
    (the still weight: the blend's half-bent legs of a start or stop would slide), and
    where a leg is blended the method's feet on the ground (the root's steps were the
    method's, scaled by the still weight); elsewhere none, the method's own pinning stands."""
    blended = (np.asarray(legs).max(axis=-1) > 0)[..., None]
    return np.maximum(np.asarray(contacts) * blended, np.asarray(body)[..., None])


def _confidence(err: np.ndarray | None, flags: np.ndarray | None, weights: np.ndarray,
                body: np.ndarray, neutral: NeutralPoses, unseen: list[int], rule: FallbackRule
                ) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The predicted error (T,) raised to what the neutral pose is expected to miss and the
    flags (T,) of frames whose unobserved groups (``unseen``) are held over
    ``rule.flag_weight`` toward it (module docstring); None stays None."""
    if err is not None:
        expected = body[..., None] * neutral.sq_error_m2[0] + (1 - body[..., None]) * \
            neutral.sq_error_m2[1]
        err = np.asarray(err, float)
        err = np.where(np.isnan(err), err, np.maximum(err, np.sqrt((weights * expected)
                                                                   .sum(-1))))
    if flags is not None:
        guess = (weights[..., unseen].max(-1) > rule.flag_weight) if unseen else \
            np.zeros(np.shape(flags), bool)
        flags = np.asarray(flags, bool) | guess
    return err, flags


def _placements(placement: str | Sequence[str]) -> list[str]:
    return [placement] if isinstance(placement, str) else list(placement)


def apply_fallback(full: Reconstruction, signals: np.ndarray, placement: str | Sequence[str],
                   neutral: NeutralPoses | None = None, rule: FallbackRule | None = None,
                   sensor: int = 0, novelty_threshold: float | None = None,
                   causal: bool = False) -> tuple[Reconstruction, FallbackReport]:
    """The per-part fallback on a method's reconstruction (module docstring).

    full : the method's :class:`~imuloco.methods.base.Reconstruction` (T frames; its
        ``scores["novelty"]`` read where it has one).
    signals : (T, 6 S) the signals it was reconstructed from, at its frame rate.
    placement : the sensors' placement(s) (their declared ``observes``, together), in the
        order of ``signals``' sensors from sensor ``sensor`` on.
    neutral : the neutral poses (default: the shipped file); rule : its settings.
    novelty_threshold : the method's :attr:`~imuloco.methods.base.Method.novelty_threshold`
        (None: the novelty is not judged).
    causal : the still weight over the past window, as the live mode reads it.

    Returns the reconstruction with its motion, ``error_m`` and ``unreliable`` changed, and
    the :class:`FallbackReport`.
    """
    rule = FallbackRule() if rule is None else rule
    neutral = NeutralPoses.load() if neutral is None else neutral
    placements = _placements(placement)
    motion = full.motion
    n = motion.num_frames
    still = np.stack([rule.still(signals[:n], motion.fps, sensor + k, causal)
                      for k in range(len(placements))], axis=1)
    still = np.pad(still, ((0, n - len(still)), (0, 0)))  # a motion longer than its signals
    novel = rule.novel((full.scores or {}).get("novelty"), n, novelty_threshold)
    weights, body = group_weights(still, novel, placements)
    moved = blend_motion(motion, weights, body, neutral)
    seen = observers(placements)
    unseen = [i for i, g in enumerate(GROUPS) if not seen[g]]
    err, flags = _confidence(full.error_m, full.unreliable, weights, body, neutral, unseen,
                             rule)
    observes = tuple(g for g in GROUPS if seen[g])
    report = FallbackReport(True, weights, body, observes, _note(placements, observes))
    return replace(full, motion=moved, error_m=err, unreliable=flags), report


def _note(placements: Sequence[str], observes: Sequence[str]) -> str:
    unseen = ", ".join(g for g in GROUPS if g not in observes) or "none"
    return (f"parts the {'+'.join(placements)} sensor{'s' if len(placements) > 1 else ''} "
            f"do{'' if len(placements) > 1 else 'es'} not observe ({unseen}) move toward a "
            "neutral pose where the model finds the motion unfamiliar, every part toward the "
            "standing pose where the sensor is still")


class FallbackStream:
    """:func:`apply_fallback` one frame at a time, causally: the live mode's
    (:class:`imuloco.app.live.session.LiveSession`). The same rule: the still weight over the
    past :attr:`FallbackRule.window_s` (``causal``), the method's novelty of the frame read;
    fed the frames :func:`apply_fallback` reads, it gives its ``causal=True`` result frame
    for frame. Bounded state: a window of sensor frames and the foot pinner's last frame.

    skeleton, fps : the method's output; placements : its sensors, in the samples' order;
    neutral : the neutral poses (default: the shipped file; a :class:`ModelFileError` when
    they do not fit ``skeleton``); novelty_threshold : the method's.
    """

    def __init__(self, skeleton: Skeleton, fps: float, placements: Sequence[str],
                 neutral: NeutralPoses | None = None, rule: FallbackRule | None = None,
                 novelty_threshold: float | None = None) -> None:
        self.rule = FallbackRule() if rule is None else rule
        self.neutral = shipped_neutral() if neutral is None else neutral
        self.blender = _Blender(skeleton, self.neutral)
        self.fps = float(fps)
        self.placements = list(placements)
        self.novelty_threshold = novelty_threshold
        seen = observers(self.placements)
        self.unseen = [i for i, g in enumerate(GROUPS) if not seen[g]]
        self.window: deque[np.ndarray] = deque(maxlen=self.rule.frames(fps))
        self.restart()

    def restart(self) -> None:
        """Forget the frames read (the method restarted after a dropout)."""
        self.window.clear()
        self.pinner = FootPinner()
        self.last: np.ndarray | None = None  # the method's previous root (3,)
        self.heading = 0.0  # the method's previous heading, radians
        self.turn = 0.0  # the turn taken back so far, radians
        self.xz = np.zeros(2)  # the held root's x, z
        self.weights = np.zeros(len(GROUPS))  # the last frame's, (G,)
        self.ankles: np.ndarray | None = None  # the method's last ankles (2, 3)
        self.legs: np.ndarray | None = None  # each leg's weight (2,), held_legs

    def step(self, sample: np.ndarray, rot: np.ndarray, root: np.ndarray,
             novelty: float | None = None, error_m: float = float("nan"),
             unreliable: bool = False) -> tuple[np.ndarray, np.ndarray, float, bool]:
        """sample : (6 S,) the sensor frame read; rot (J, 4), root (3,) the method's pose;
        novelty, error_m, unreliable : its confidence -> the pose and confidence after the
        fallback."""
        sample = np.asarray(sample, dtype=np.float64)
        if not self.window:  # the first frame repeated before the start (causal still)
            self.window.extend([sample] * self.window.maxlen)
        self.window.append(sample)
        win = np.stack(self.window).reshape(len(self.window), -1, 6)  # (W, S, 6)
        var = (win * win).mean(0) - win.mean(0) ** 2
        still = self.rule.still_of(np.stack([var[:, :3].sum(1), var[:, 3:].sum(1)], 1))
        novel = self.rule.novel(None if novelty is None else np.array([novelty]), 1,
                                self.novelty_threshold)
        weights, body = group_weights(still[None], novel, self.placements)
        self.weights = weights[0]
        rot = normalize(np.asarray(rot, dtype=np.float64))[None]
        heading = self.blender.heading(rot)
        root = np.asarray(root, dtype=np.float64)
        sk = self.blender.skeleton
        ankles = joint_positions(rot[0], root, sk.offsets, sk.parents, self.blender.pinned)
        contact = self.rule.contacts(ankles[None], self.fps, self.blender.leg_m,
                                     self.ankles)[0]
        self.ankles = ankles
        w = weights[0, GROUPS.index("legs")]
        self.legs = np.full(2, w) if self.legs is None else np.where(contact, self.legs, w)
        if self.last is None:
            self.xz = root[[0, 2]]
        else:
            turn = heading[0] - self.heading  # as np.unwrap reads it
            self.turn -= body[0] * (turn - 2 * np.pi * np.round(turn / (2 * np.pi)))
            step = np.zeros(3)
            step[[0, 2]] = (1.0 - body[0]) * (root[[0, 2]] - self.last[[0, 2]])
            self.xz = self.xz + qrot(about_y(np.array(self.turn)), step)[[0, 2]]
        self.last, self.heading = root.copy(), heading[0]
        out, feet_y = self.blender.pose(rot, weights, body, heading, np.array([self.turn]),
                                        self.legs[None])
        held = np.array([self.xz[0], self.blender.height(root[1], feet_y[0], body[0]),
                         self.xz[1]])
        rel = joint_positions(out[0], np.zeros(3), sk.offsets, sk.parents, self.blender.pinned)
        held = self.pinner.step(held, rel, _pinned(contact, self.legs, body[0]))
        err, flag = _confidence(np.array([error_m]), np.array([unreliable]), weights, body,
                                self.neutral, self.unseen, self.rule)
        return out[0], held, float(err[0]), bool(flag[0])


@lru_cache(maxsize=1)
def shipped_neutral() -> NeutralPoses:
    """The neutral poses shipped beside the models (read once)."""
    return NeutralPoses.load()


def fallback_recording(full: Reconstruction, rec: Recording, method: Method
                       ) -> tuple[Reconstruction, FallbackReport]:
    """:func:`apply_fallback` on ``method``'s reconstruction ``full`` of ``rec`` (calibrated,
    as the method read it) with the shipped neutral poses and the method's own novelty
    threshold: the pipeline's one call (:func:`imuloco.app.pipeline.reconstruct_recording`).
    A model whose skeleton the neutral poses do not fit is left as it is, and the report says
    why."""
    signals = model_frames(rec.select(method.placements_), method.fps_, method.gaps_missing)
    return fallback_signals(full, signals, method)


def fallback_signals(full: Reconstruction, signals: np.ndarray, method: Method
                     ) -> tuple[Reconstruction, FallbackReport]:
    """:func:`fallback_recording` on the signals (T, 6 S) ``method`` read at its frame rate
    (a piece of a recording with its warm-up: :mod:`imuloco.app.chunked`)."""
    neutral = shipped_neutral()
    try:
        neutral.on(full.motion.skeleton)
    except ModelFileError as e:
        return full, FallbackReport(True, note=f"not applied: {e}")
    return apply_fallback(full, signals, method.placements_, neutral,
                          novelty_threshold=method.novelty_threshold)
