"""Evaluation protocols, fixed in code and versioned so that results can be compared.

- ``random-clips``: a clip is in the test set when the CRC32 of its file name falls in the
  lowest 20 % of the hash range (stable across machines and runs; about 20 % of clips).
- ``heldout-styles``: clips of the styles ``exhausted`` and ``feminine`` form the test set.

Test recordings are simulated with seeds offset by
:data:`imuloco.methods.training.TEST_SEED_OFFSET`, never shared with training.
"""

from __future__ import annotations

import zlib

from imuloco.core.motion import MotionDatabase
from imuloco.errors import UnknownNameError

PROTOCOL_VERSION = 1
SPLITS = ("random-clips", "heldout-styles")
MOTION_TYPES = ("walk", "walk-turn-left", "walk-turn-right", "run")
HELDOUT_STYLES = ("exhausted", "feminine")
TEST_FRACTION = 0.2


def in_random_test(name: str) -> bool:
    """Whether a clip (by file name, without folder) is in the ``random-clips`` test set."""
    return zlib.crc32(name.encode()) < TEST_FRACTION * 2**32


def split(db: MotionDatabase, name: str) -> tuple[MotionDatabase, MotionDatabase]:
    """Training and test databases of protocol ``name`` (one of :data:`SPLITS`)."""
    if name == "random-clips":
        test = [in_random_test(lab["name"]) for lab in db.labels]
    elif name == "heldout-styles":
        test = [lab.get("style") in HELDOUT_STYLES for lab in db.labels]
    else:
        raise UnknownNameError(f"unknown split {name!r}; splits: {list(SPLITS)}")
    train_idx = [i for i, t in enumerate(test) if not t]
    test_idx = [i for i, t in enumerate(test) if t]
    if not train_idx or not test_idx:
        raise ValueError(f"split {name!r} leaves an empty training or test set "
                         f"({len(train_idx)} / {len(test_idx)} clips)")
    return db.subset(train_idx), db.subset(test_idx)
