"""Heading frames: the body's facing direction about the vertical axis.

World axes are Y up (as in BVH). A person facing +Z has their left side on +X. The heading
angle ``theta`` is the rotation about +Y that turns +Z into the facing direction, which is taken
from the hip line (left hip minus right hip) crossed with the vertical, as the 2014 and 2017
papers' heading-frame errors use.
"""

from __future__ import annotations

import numpy as np

from imuloco.ops.rotations import about_y, qinv, qrot

UP = np.array([0.0, 1.0, 0.0])


def heading_from_hips(left_hip: np.ndarray, right_hip: np.ndarray) -> np.ndarray:
    """Heading angle (radians) from hip positions. left_hip, right_hip : (..., 3) -> (...)."""
    across = np.asarray(left_hip) - np.asarray(right_hip)
    forward = np.cross(across, UP)
    return np.arctan2(forward[..., 0], forward[..., 2])


def to_heading_frame(points: np.ndarray, origin: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Express world points in the heading frame at ``origin``: translate, then remove the yaw.
    points : (..., N, 3), origin : (..., 3), theta : (...) -> (..., N, 3)."""
    q = qinv(about_y(theta))[..., None, :]
    return qrot(q, np.asarray(points) - np.asarray(origin)[..., None, :])


def wrap_angle(a: np.ndarray) -> np.ndarray:
    """Angles wrapped to (-pi, pi]."""
    return np.angle(np.exp(1j * np.asarray(a)))
