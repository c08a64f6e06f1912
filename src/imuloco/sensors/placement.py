"""Sensor placements: where a sensor rides on the body and how it is turned.

A placement is a body segment (the joint whose frame the sensor follows), a point on it and a
fixed rotation. Both are given in the segment's *anatomical frame*, built from the rest pose so
that presets mean the same on any skeleton: ``y`` runs along the segment towards its proximal
end (up the shin for an ankle sensor, as a phone strapped on the shin reads +g on y at rest),
``z`` points forward (anterior, from the body's facing direction at rest) and ``x = y x z``
(to the body's left). For the trunk and head, ``y`` is the body's up direction.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from imuloco.core.skeleton import Skeleton
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
    """

    name: str
    segment: str
    toward: str | None = None
    fraction: float = 0.0
    surface: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)

    def perturbed(self, rotation: np.ndarray, offset: np.ndarray) -> Placement:
        """The same placement with an extra misalignment rotation and offset (metres, in the
        anatomical frame), as when a phone is strapped slightly off."""
        rot = qmul(np.asarray(self.rotation), np.asarray(rotation))
        return replace(self, rotation=tuple(rot), surface=tuple(np.add(self.surface, offset)))


PRESETS: dict[str, Placement] = {p.name: p for p in [
    # On the front of the shank just above the ankle, where Eom et al. 2014 strap the phone.
    Placement("right_ankle", "right_knee", "right_ankle", 0.8, (0.0, 0.0, 0.045)),
    Placement("left_ankle", "left_knee", "left_ankle", 0.8, (0.0, 0.0, 0.045)),
    # Front trouser pocket: upper third of the thigh, towards the outside.
    Placement("right_thigh", "right_hip", "right_knee", 0.3, (-0.04, 0.0, 0.07)),
    Placement("left_thigh", "left_hip", "left_knee", 0.3, (0.04, 0.0, 0.07)),
    # Belt buckle, in front of the pelvis.
    Placement("pelvis", "pelvis", None, 0.0, (0.0, 0.0, 0.12)),
    # Watch on the back of the forearm just above the wrist.
    Placement("right_wrist", "right_elbow", "right_wrist", 0.9, (0.0, 0.0, 0.03)),
    Placement("left_wrist", "left_elbow", "left_wrist", 0.9, (0.0, 0.0, 0.03)),
    # Phone held in the hand: past the wrist along the forearm's axis.
    Placement("right_hand", "right_wrist", None, 0.0, (0.0, -0.07, 0.0)),
    Placement("left_hand", "left_wrist", None, 0.0, (0.0, -0.07, 0.0)),
    Placement("chest", "chest", None, 0.0, (0.0, 0.0, 0.12)),
    Placement("head", "head", None, 0.0, (0.0, 0.08, 0.1)),
]}


def get_placement(name: str | Placement) -> Placement:
    """A preset by name (or a Placement passed through)."""
    if isinstance(name, Placement):
        return name
    if name not in PRESETS:
        raise KeyError(f"unknown sensor placement {name!r}; presets: {sorted(PRESETS)}")
    return PRESETS[name]


def _body_axes(pos: np.ndarray, sk: Skeleton) -> tuple[np.ndarray, np.ndarray]:
    """Body up and left directions in the rest pose. pos : (J, 3)."""
    up = pos[sk.part("neck")] - pos[sk.part("pelvis")]
    up /= np.linalg.norm(up)
    left = pos[sk.part("left_hip")] - pos[sk.part("right_hip")]
    left -= up * (left @ up)
    return up, left / np.linalg.norm(left)


def anatomical_frame(sk: Skeleton, placement: Placement) -> tuple[int, np.ndarray, np.ndarray]:
    """The sensor's rigid attachment to its joint.

    Returns
    -------
    joint : index of the joint whose frame the sensor follows.
    offset : ndarray, shape (3,), sensor position in that joint's local frame (metres).
    rotation : ndarray, shape (4,), sensor-to-joint-frame quaternion x, y, z, w.
    """
    rest_rot = np.tile(IDENTITY, (sk.num_joints, 1))
    grot, pos = fk(rest_rot, np.zeros(3), sk.offsets, sk.parents)
    up, left = _body_axes(pos, sk)
    joint = sk.part(placement.segment)
    origin = pos[joint]
    y = up
    if placement.toward is not None:
        end = pos[sk.part(placement.toward)]
        y = origin - end
        y /= np.linalg.norm(y)
        origin = origin + placement.fraction * (end - origin)
    elif placement.segment.endswith("wrist") or placement.segment.endswith("hand"):
        elbow = pos[sk.part(placement.segment.replace("wrist", "elbow"))]
        y = elbow - origin
        y /= np.linalg.norm(y)
    forward = np.cross(left, up)
    z = forward - y * (forward @ y)
    if np.linalg.norm(z) < 1e-6:  # a segment along the facing direction: use the left axis
        z = np.cross(y, left)
    z /= np.linalg.norm(z)
    x = np.cross(y, z)
    anat = from_matrix(np.stack([x, y, z], axis=1))  # anatomical -> world, at rest
    world_point = origin + qrot(anat, np.asarray(placement.surface))
    joint_inv = qinv(grot[joint])
    offset = qrot(joint_inv, world_point - pos[joint])
    rotation = qmul(joint_inv, qmul(anat, np.asarray(placement.rotation)))
    return joint, offset, rotation
