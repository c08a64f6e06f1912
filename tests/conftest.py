"""Shared fixtures: tiny generated skeletons and motions, the bundled sample, ../shared data."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from imuloco.core.motion import Motion
from imuloco.core.skeleton import Skeleton
from imuloco.data import shared_data_dir
from imuloco.ops.rotations import about_y


@pytest.fixture(scope="session")
def shared_dir() -> Path:
    """``../shared/data/bandai-namco-2``; tests that use it are skipped when it is absent."""
    d = shared_data_dir()
    if d is None:
        pytest.skip("../shared data is absent")
    return d


@pytest.fixture(scope="session")
def sample_db():
    from imuloco.io.database import load_sample

    return load_sample()


@pytest.fixture
def two_joint_skeleton() -> Skeleton:
    """A root with one child 1 m above it along +Y."""
    return Skeleton(["root", "child"], np.array([-1, 0]), np.array([[0, 0, 0], [0, 1.0, 0]]))


@pytest.fixture
def spinning_motion(two_joint_skeleton: Skeleton) -> Motion:
    """The two-joint skeleton spinning about +Y at 1 rad/s for 3 s at 30 fps."""
    t = np.arange(90) / 30.0
    rot = np.zeros((90, 2, 4))
    rot[:, 0] = about_y(t)
    rot[:, 1, 3] = 1.0
    return Motion(two_joint_skeleton, rot, np.zeros((90, 3)), 30.0, "spin")
