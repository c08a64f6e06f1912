"""The per-part fallback (issue 41): where the sensor says the legs stand still, or the model
does not know the motion and a body part is one the sensor cannot see, that part of the
reconstruction moves toward a neutral pose of the detected activity instead of an invented
one, and the predicted error rises to what the neutral pose is expected to miss.

The rule (:func:`apply_fallback`), per frame:

- **activity**: the sensor's own motion energy over a centred window of
  :attr:`FallbackRule.window_s` seconds (the standard deviation of the gyro and of the
  accelerometer about their window means, so that a bias does not count). Under
  ``still_gyro`` rad/s and ``still_acc`` m/s^2 the sensor is *still* (weight 1), over
  ``ramp`` times both it *moves* (0), smoothly between (:func:`smoothstep` on the larger of
  the two ratios). Standing gestures read 0.06-0.09 rad/s on a simulated shin phone, walking
  2-3.5 (``docs/results/actions/fallback.md``).
- **novelty**: the method's own score (``learned``: how far the network's features lie from
  its training data's, 1 on familiar motion, :mod:`imuloco.methods.learned.confidence`), 0
  at ``novelty_low`` (where the shipped model starts flagging frames) and 1 at
  ``novelty_high``, smoothly between; methods without a novelty score give 0.
- **observed parts**: the placement declares which body-part groups
  (:data:`imuloco.core.bodymap.PART_GROUPS`) its sensor sees
  (:attr:`imuloco.sensors.placement.Placement.observes`: a shin its leg, the lower back the
  trunk). A group's weight is the still weight for an observed group, the larger of the still
  and novelty weights for an unobserved one.
- **the neutral pose** of the frame is the standing pose where still, the walking mean pose
  where moving, slerped between by the still weight (:class:`NeutralPoses`, built from
  training motion by :func:`imuloco.lab.neutral.build_neutral`). Each joint's local rotation
  is slerped toward it by its group's weight (the pelvis's tilt against its heading with the
  legs'); where the legs stand still the root stops (its horizontal steps scaled by one minus
  the still weight), its height is the standing pose's over the floor and both feet are
  pinned (:func:`imuloco.methods.postprocess.pin_feet`, contact weight the still weight), so
  no phantom step remains for the gait, the strides and the path follower.
- **predicted error**: at least ``sqrt(sum_g w_g S_g)``, with ``S_g`` the neutral pose's
  expected squared error of the joints group ``g`` moves over the frame's joint count, on its
  activity (measured by :func:`imuloco.lab.neutral.build_neutral`); frames where an
  unobserved part is held more than half way toward neutral are flagged unreliable (the pose
  there is a guess).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
from scipy.ndimage import uniform_filter1d

from imuloco.core.bodymap import PART_GROUPS
from imuloco.core.motion import Motion
from imuloco.core.recording import Recording
from imuloco.core.skeleton import Skeleton
from imuloco.errors import ModelFileError
from imuloco.io.atomic import atomic_write
from imuloco.methods import pose
from imuloco.methods.base import Method, Reconstruction
from imuloco.methods.postprocess import pin_feet
from imuloco.methods.training import model_frames
from imuloco.ops.rotations import (
    about_y,
    normalize,
    qinv,
    qmul,
    slerp_toward,
)
from imuloco.sensors.placement import get_placement

GROUPS = tuple(PART_GROUPS)  # ("legs", "arms", "trunk")
ACTIVITIES = ("still", "moving")
NEUTRAL_FILE = "neutral_poses.npz"  # beside the shipped models (imuloco.data.MODELS_DIR)
FEET = ("left_ankle", "left_toe", "right_ankle", "right_toe")


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

    window_s : seconds of the centred window the sensor's energy is read over.
    still_gyro, still_acc : rad/s and m/s^2 under which the sensor is still (the standard
        deviations of the gyro's and the accelerometer's 3 axes together over the window).
    ramp : over ``ramp`` times those the sensor moves (weight 0).
    novelty_low, novelty_high : the method's novelty score at which an unobserved part starts
        to move toward neutral and at which it is there: the shipped shin model's own flag
        threshold (3.62, the 99 % quantile of held-out training-motion novelty) and 1.5 times
        it (at 1.5 and 3.0 the arms of runs and dashes, motion the model knows but whose
        novelty reads 2-4, fell to the walking pose: dash 3.9 -> 8.0 cm MPJPE).
    flag_weight : frames where an unobserved part's weight is over this are flagged.
    """

    window_s: float = 1.0
    still_gyro: float = 0.3
    still_acc: float = 1.0
    ramp: float = 2.5
    novelty_low: float = 3.6
    novelty_high: float = 5.4
    flag_weight: float = 0.5

    def still(self, signals: np.ndarray, fps: float, sensor: int = 0) -> np.ndarray:
        """Still weight (T,) in [0, 1] of sensor ``sensor`` of ``signals`` (T, 6 S) at
        ``fps``: 1 still, 0 moving (NaN rows, a gap, read as moving)."""
        s = np.asarray(signals, dtype=np.float64)[:, 6 * sensor:6 * sensor + 6]
        if not len(s):
            return np.zeros(0)
        w = max(1, round(self.window_s * fps) | 1)
        mean = uniform_filter1d(s, w, axis=0, mode="nearest")
        var = uniform_filter1d(s * s, w, axis=0, mode="nearest") - mean * mean
        std = np.sqrt(np.maximum(np.stack([var[:, :3].sum(1), var[:, 3:].sum(1)], 1), 0.0))
        level = np.maximum(std[:, 1] / self.still_gyro, std[:, 0] / self.still_acc)
        out = 1.0 - smoothstep((level - 1.0) / (self.ramp - 1.0))
        return np.where(np.isfinite(out), out, 0.0)

    def novel(self, novelty: np.ndarray | None, frames: int) -> np.ndarray:
        """Novelty weight (T,) in [0, 1] from a method's novelty score (None: zeros)."""
        if novelty is None:
            return np.zeros(frames)
        x = (np.asarray(novelty, float) - self.novelty_low) / (self.novelty_high
                                                               - self.novelty_low)
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


def group_weights(still: np.ndarray, novel: np.ndarray, observes: Sequence[str]) -> np.ndarray:
    """Each group's weight toward neutral (T, G): the still weight for an observed group,
    the larger of the still and novelty weights for one the sensor does not see."""
    return np.stack([still if g in observes else np.maximum(still, novel) for g in GROUPS], 1)


def blend_motion(motion: Motion, weights: np.ndarray, still: np.ndarray,
                 neutral: np.ndarray, clearance_m: float) -> Motion:
    """``motion`` moved toward the neutral poses per group (module docstring).

    weights : (T, G) per group; still : (T,) the still weight; neutral : (A, J, 4) the
    activities' poses on the motion's skeleton (:meth:`NeutralPoses.on`); clearance_m : the
    standing pose's lowest foot joint over the floor."""
    sk, n = motion.skeleton, motion.num_frames
    if n == 0:
        return motion
    rot_groups = joint_groups(sk)
    legs = GROUPS.index("legs")
    wj = weights[:, np.where(rot_groups >= 0, rot_groups, legs)]  # (T, J); the root: legs
    target = slerp_toward(np.broadcast_to(neutral[1], (n, *neutral[1].shape)),
                    np.broadcast_to(neutral[0], (n, *neutral[0].shape)),
                    np.broadcast_to(still[:, None], (n, sk.num_joints)))
    yaw = about_y(np.unwrap(pose.heading(motion)))
    rot = normalize(motion.rotations).copy()
    tilt = qmul(qinv(yaw), rot[:, 0])
    rot[:, 0] = qmul(yaw, slerp_toward(tilt, target[:, 0], wj[:, 0]))
    rot[:, 1:] = slerp_toward(rot[:, 1:], target[:, 1:], wj[:, 1:])
    root = motion.root.copy()
    steps = np.diff(motion.root[:, [0, 2]], axis=0) * (1.0 - still[1:, None])
    root[1:, [0, 2]] = motion.root[0, [0, 2]] + np.cumsum(steps, axis=0)
    held = Motion(sk, rot, np.zeros_like(root), motion.fps)
    feet = held.part_positions(list(FEET))[..., 1].min(axis=1)  # lowest foot joint, root at 0
    root[:, 1] = (1.0 - still) * motion.root[:, 1] + still * (clearance_m - feet)
    out = Motion(sk, rot, root, motion.fps, motion.name)
    if n < 2 or not still.any():
        return out
    # where the legs stand, both feet are on the floor: the root steps so that they do not
    # slide (the blend's half-bent legs of a start or stop would), weighted by the still weight
    return pin_feet(out, np.stack([still, still], axis=1))


def apply_fallback(full: Reconstruction, signals: np.ndarray, placement: str,
                   neutral: NeutralPoses | None = None, rule: FallbackRule | None = None,
                   sensor: int = 0) -> tuple[Reconstruction, FallbackReport]:
    """The per-part fallback on a method's reconstruction (module docstring).

    full : the method's :class:`~imuloco.methods.base.Reconstruction` (T frames; its
        ``scores["novelty"]`` read where it has one).
    signals : (T, 6 S) the signals it was reconstructed from, at its frame rate.
    placement : the sensor's placement (its declared ``observes``).
    neutral : the neutral poses (default: the shipped file); rule : its settings.
    sensor : which sensor of ``signals`` is ``placement``'s.

    Returns the reconstruction with its motion, ``error_m`` and ``unreliable`` changed, and
    the :class:`FallbackReport`.
    """
    rule = FallbackRule() if rule is None else rule
    neutral = NeutralPoses.load() if neutral is None else neutral
    motion = full.motion
    n = motion.num_frames
    observes = tuple(get_placement(placement).observes)
    still = rule.still(signals[:n], motion.fps, sensor)
    still = np.pad(still, (0, n - len(still)))  # a motion longer than its signals: moving
    novel = rule.novel((full.scores or {}).get("novelty"), n)
    weights = group_weights(still, novel, observes)
    moved = blend_motion(motion, weights, still, neutral.on(motion.skeleton),
                         neutral.clearance_m)
    err, flags = full.error_m, full.unreliable
    if err is not None:
        expected = still[:, None] * neutral.sq_error_m2[0] + (1 - still[:, None]) * \
            neutral.sq_error_m2[1]
        err = np.asarray(err, float)
        err = np.where(np.isnan(err), err, np.maximum(err, np.sqrt((weights * expected).sum(1))))
    if flags is not None:
        unseen = [i for i, g in enumerate(GROUPS) if g not in observes]
        guess = (weights[:, unseen].max(1) > rule.flag_weight) if unseen else np.zeros(n, bool)
        flags = np.asarray(flags, bool) | guess
    unseen_names = ", ".join(g for g in GROUPS if g not in observes) or "none"
    note = (f"parts the {placement} sensor does not observe ({unseen_names}) move toward a neutral pose where the model finds the motion unfamiliar, every "
            "part toward the standing pose where the sensor is still")
    report = FallbackReport(True, weights, still, observes, note)
    return replace(full, motion=moved, error_m=err, unreliable=flags), report


@lru_cache(maxsize=1)
def shipped_neutral() -> NeutralPoses:
    """The neutral poses shipped beside the models (read once)."""
    return NeutralPoses.load()


def fallback_recording(full: Reconstruction, rec: Recording, method: Method
                       ) -> tuple[Reconstruction, FallbackReport]:
    """:func:`apply_fallback` on ``method``'s reconstruction ``full`` of ``rec`` (calibrated,
    as the method read it) with the shipped neutral poses: the pipeline's one call
    (:func:`imuloco.app.pipeline.reconstruct_recording`). A model whose skeleton the neutral
    poses do not fit is left as it is, and the report says why."""
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
    return apply_fallback(full, signals, method.placements_[0], neutral)
