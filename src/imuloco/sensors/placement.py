"""Sensor placements: where a sensor rides on the body and how it is turned.

A placement is a body segment (the joint whose frame the sensor follows), a point on it and a
fixed rotation. Both are given in the segment's *anatomical frame*, built from the rest pose so
that presets mean the same on any skeleton: ``y`` runs along the segment towards its proximal
end (up the shin for an ankle sensor, as a phone strapped on the shin reads +g on y at rest),
``z`` points forward (anterior, from the body's facing direction at rest) and ``x = y x z``
(to the body's left). For the trunk and head, ``y`` is the body's up direction.

Each preset is also the placement's one declaration for the rest of the package (the
placement registry, :data:`PRESETS`): how a worn sensor there is calibrated (``mounting``, a
routine of :data:`imuloco.sensors.calibration.MOUNTINGS`), which estimator measures its gait
from its own signal (``gait``, one of :data:`imuloco.measures.sensorgait.ESTIMATORS`; none:
the reconstructed motion's gait), the optional extra those need (``extra``, ``needs``), the
shipped model's name (``imuloco/data/models/<method>_<model>.npz``) and the estimator of the
walker's path (``path_estimator``, a name :mod:`imuloco.paths.registry` resolves). The
routines are named, not referenced: they live in the layers that read this one.
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass, replace
from importlib.util import find_spec

import numpy as np
from scipy.spatial.transform import Rotation

from imuloco.core.skeleton import Skeleton
from imuloco.errors import MissingExtraError, UnknownNameError
from imuloco.ops.kinematics import fk
from imuloco.ops.rotations import IDENTITY, from_matrix, qinv, qmul, qrot


@dataclass(frozen=True)
class Placement:
    """Where a sensor sits.

    Attributes
    ----------
    name : preset name, e.g. ``"right_ankle"``.
    segment : body part whose joint frame the sensor follows (``"right_knee"`` for the shank).
    toward : the distal body part that gives the segment's long axis (``None`` for trunk/head).
    fraction : position along the segment, 0 at ``segment``'s joint and 1 at ``toward``.
    surface : offset from that point in the anatomical frame (x left, y up the segment,
        z forward), metres: how far the skin or pocket sits from the bone.
    rotation : quaternion x, y, z, w from the sensor frame to the anatomical frame.
    mounting : how a worn sensor is turned into the anatomical frame, a routine of
        :data:`imuloco.sensors.calibration.MOUNTINGS` (``None``: not calibrated).
    gait : the estimator of gait from this sensor's own signal, a name of
        :data:`imuloco.measures.sensorgait.ESTIMATORS` (``None``: the reconstructed motion's).
    extra, needs : the optional extra (``pip install 'imuloco[extra]'``) and the modules of it
        the calibration and gait need (:meth:`require_extra`).
    model : name of the shipped pretrained models (``<method>_<model>.npz``; ``None``: none).
    path_estimator : name of the estimator of the walker's path (:mod:`imuloco.paths`;
        ``None``: the method's own root path).
    observes : the body-part groups (:data:`imuloco.core.bodymap.PART_GROUPS`) the sensor
        sees: a leg sensor its leg (``legs``), the lower back the trunk; the others fall
        back toward a neutral pose where the model does not know the motion
        (:mod:`imuloco.methods.fallback`).
    """

    name: str
    segment: str
    toward: str | None = None
    fraction: float = 0.0
    surface: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)
    mounting: str | None = None
    gait: str | None = None
    extra: str | None = None
    needs: tuple[str, ...] = ()
    model: str | None = None
    path_estimator: str | None = None
    observes: tuple[str, ...] = ()

    @property
    def side(self) -> str | None:
        """``"left"`` or ``"right"`` for a limb's placement, ``None`` on the trunk and head."""
        side = self.segment.split("_")[0]
        return side if side in ("left", "right") else None

    def require_extra(self) -> None:
        """Raise :class:`~imuloco.errors.MissingExtraError` (``pip install 'imuloco[gait]'``)
        when a module this placement's calibration and gait need (``needs``) is missing."""
        missing = next((m for m in self.needs if find_spec(m) is None), None)
        if missing is not None:
            raise MissingExtraError(f"a {self.name} sensor's calibration and gait",
                                    self.needs[0], self.extra or "gait")

    @property
    def on_shank(self) -> bool:
        """Whether the sensor rides on a shank (knee to ankle), whose swing it reads."""
        return self.segment.endswith("_knee") and (self.toward or "").endswith("_ankle")

    def perturbed(self, rotation: np.ndarray, offset: np.ndarray) -> Placement:
        """The same placement with an extra misalignment rotation and offset (metres, in the
        anatomical frame), as when a phone is strapped slightly off."""
        rot = qmul(np.asarray(self.rotation), np.asarray(rotation))
        return replace(self, rotation=tuple(rot), surface=tuple(np.add(self.surface, offset)))


# A shoe sensor's calibration and gait read its zero-velocity track (gaitmap), a lower-back
# sensor's gait Mobilise-D's pipeline (mobgap): the [gait] extra, with pandas.
_FOOT = {"observes": ("legs",), "mounting": "foot", "gait": "foot", "extra": "gait", "needs": ("gaitmap", "pandas"),
         "path_estimator": "foot-zupt"}
_BACK = {"observes": ("trunk",), "mounting": "lower_back", "gait": "lower_back", "extra": "gait",
         "needs": ("mobgap", "pandas"), "path_estimator": "lower-back-steps"}

PRESETS: dict[str, Placement] = {p.name: p for p in [
    # On the front of the shank just above the ankle, where Eom et al. 2014 strap the phone.
    Placement("right_ankle", "right_knee", "right_ankle", 0.8, (0.0, 0.0, 0.045),
              mounting="shank", model="right_ankle", path_estimator="shank-pivot",
              observes=("legs",)),
    Placement("left_ankle", "left_knee", "left_ankle", 0.8, (0.0, 0.0, 0.045),
              mounting="shank", model="left_ankle", path_estimator="shank-pivot",
              observes=("legs",)),
    # Front trouser pocket: upper third of the thigh, towards the outside.
    Placement("right_thigh", "right_hip", "right_knee", 0.3, (-0.04, 0.0, 0.07),
              mounting="thigh", observes=("legs",)),
    Placement("left_thigh", "left_hip", "left_knee", 0.3, (0.04, 0.0, 0.07), mounting="thigh", observes=("legs",)),
    # Belt buckle, in front of the pelvis.
    Placement("pelvis", "pelvis", None, 0.0, (0.0, 0.0, 0.12), observes=("trunk",)),
    # Watch on the back of the forearm just above the wrist.
    Placement("right_wrist", "right_elbow", "right_wrist", 0.9, (0.0, 0.0, 0.03),
              observes=("arms",)),
    Placement("left_wrist", "left_elbow", "left_wrist", 0.9, (0.0, 0.0, 0.03),
              observes=("arms",)),
    # Phone held in the hand: past the wrist along the forearm's axis.
    Placement("right_hand", "right_wrist", None, 0.0, (0.0, -0.07, 0.0), observes=("arms",)),
    Placement("left_hand", "left_wrist", None, 0.0, (0.0, -0.07, 0.0), observes=("arms",)),
    Placement("chest", "chest", None, 0.0, (0.0, 0.0, 0.12), observes=("trunk",)),
    # On the shoe over the instep, where foot-worn gait sensors sit: half way from the ankle
    # joint to the toe joint, 4 cm above the bones. The foot's anatomical y runs back to the
    # heel and z up off the instep (dorsal), so a flat foot reads +g on z.
    Placement("right_foot", "right_ankle", "right_toe", 0.5, (0.0, 0.0, 0.04), **_FOOT,
              model="right_foot"),
    Placement("left_foot", "left_ankle", "left_toe", 0.5, (0.0, 0.0, 0.04), **_FOOT,
              model="left_foot"),
    # At L5, the back of the belt: behind the pelvis joint, y up the trunk.
    Placement("lower_back", "pelvis", None, 0.0, (0.0, 0.0, -0.10), **_BACK,
              model="lower_back"),
    Placement("head", "head", None, 0.0, (0.0, 0.08, 0.1), observes=("trunk",)),
]}


def get_placement(name: str | Placement) -> Placement:
    """A preset by name (or a Placement passed through)."""
    if isinstance(name, Placement):
        return name
    if name not in PRESETS:
        close = difflib.get_close_matches(str(name), list(PRESETS), n=2, cutoff=0.6)
        hint = f"did you mean {' or '.join(map(repr, close))}? " if close else ""
        raise UnknownNameError(f"unknown sensor placement {name!r}; {hint}presets: "
                               f"{sorted(PRESETS)}")
    return PRESETS[name]


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _body_axes(pos: np.ndarray, sk: Skeleton) -> tuple[np.ndarray, np.ndarray]:
    """Body up and left directions. pos : (..., J, 3) -> (..., 3), (..., 3)."""
    up = _unit(pos[..., sk.part("neck"), :] - pos[..., sk.part("pelvis"), :])
    left = pos[..., sk.part("left_hip"), :] - pos[..., sk.part("right_hip"), :]
    left = left - up * np.sum(left * up, axis=-1, keepdims=True)
    return up, _unit(left)


def _axes(sk: Skeleton, placement: Placement, pos: np.ndarray
          ) -> tuple[np.ndarray, np.ndarray]:
    """Anatomical-to-world rotation (..., 4) and sensor origin (..., 3) in poses with joint
    positions ``pos`` (..., J, 3)."""
    up, left = _body_axes(pos, sk)
    joint = sk.part(placement.segment)
    origin = pos[..., joint, :]
    y = up
    if placement.toward is not None:
        end = pos[..., sk.part(placement.toward), :]
        y = _unit(origin - end)
        origin = origin + placement.fraction * (end - origin)
    elif placement.segment.endswith("wrist") or placement.segment.endswith("hand"):
        elbow = pos[..., sk.part(placement.segment.replace("wrist", "elbow")), :]
        y = _unit(elbow - origin)
    forward = np.cross(left, up)
    z = forward - y * np.sum(forward * y, axis=-1, keepdims=True)
    # a segment along the facing direction: use the left axis
    z = np.where(np.linalg.norm(z, axis=-1, keepdims=True) < 1e-6, np.cross(y, left), z)
    z = _unit(z)
    return from_matrix(np.stack([np.cross(y, z), y, z], axis=-1)), origin


def anatomical_frame(sk: Skeleton, placement: Placement, pose: np.ndarray | None = None
                     ) -> tuple[int, np.ndarray, np.ndarray]:
    """The sensor's rigid attachment to its joint, built in the skeleton's rest pose.

    The rest pose fixes the segment's long axis (y) in the joint's frame, but not always its
    twist: the Bandai-Namco BVH rest pose has the legs in a split, its right leg turned half a
    turn about its own axis and its chest a quarter turn in every motion frame, so frames built
    at rest face backwards or sideways during motion. Given ``pose`` (motion frames), the rest
    frame of a leg or trunk placement is turned about y by the multiple of a quarter turn
    nearest to the mean twist between it and the frames built in those poses (forward from the
    hip line, up from pelvis to neck). The result stays the skeleton's (one of four fixed
    choices, the same for every clip of the sample), not the clip's. Arm placements keep the
    rest frame: the forearm's twist relative to the body's forward varies too much.

    Parameters
    ----------
    pose : ndarray, shape (J, 4) or (T, J, 4), optional local rotations of poses the body
        takes (x, y, z, w), used only for that half-turn decision.

    Returns
    -------
    joint : index of the joint whose frame the sensor follows.
    offset : ndarray, shape (3,), sensor position in that joint's local frame (metres).
    rotation : ndarray, shape (4,), sensor-to-joint-frame quaternion x, y, z, w.
    """
    rest_rot = np.tile(IDENTITY, (sk.num_joints, 1))
    grot, pos = fk(rest_rot, np.zeros(3), sk.offsets, sk.parents)
    joint = sk.part(placement.segment)
    anat, origin = _axes(sk, placement, pos)  # anatomical -> world, at rest
    arm = any(k in placement.segment for k in ("elbow", "wrist", "hand", "shoulder"))
    if pose is not None and not arm:
        pose = np.asarray(pose, dtype=np.float64).reshape(-1, sk.num_joints, 4)
        pg, pp = fk(pose, np.zeros((len(pose), 3)), sk.offsets, sk.parents)
        posed, _ = _axes(sk, placement, pp)
        # the posed frames in the joint's frame, against the rest frame in the joint's frame
        rel = qmul(qinv(qmul(qinv(grot[joint]), anat)), qmul(qinv(pg[:, joint]), posed))
        twist = Rotation.from_quat(rel).mean().as_quat()
        twist = twist if twist[3] >= 0 else -twist
        quarter = np.round(2 * np.arctan2(twist[1], twist[3]) / (np.pi / 2)) * (np.pi / 2)
        anat = qmul(anat, np.array([0.0, np.sin(quarter / 2), 0.0, np.cos(quarter / 2)]))
    world_point = origin + qrot(anat, np.asarray(placement.surface))
    joint_inv = qinv(grot[joint])
    offset = qrot(joint_inv, world_point - pos[joint])
    rotation = qmul(joint_inv, qmul(anat, np.asarray(placement.rotation)))
    return joint, offset, rotation
