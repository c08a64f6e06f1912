"""Evaluation protocols, fixed in code and versioned so that results can be compared.

- ``random-clips``: a clip is in the test set when the CRC32 of its file name falls in the
  lowest 20 % of the hash range (stable across machines and runs; about 20 % of clips).
- ``heldout-styles``: clips of the styles ``exhausted`` and ``feminine`` form the test set.
- ``heldout-contents``: one fold per content of :data:`HELDOUT_CONTENTS` present in the data
  (meant for both Bandai-Namco sets together): its clips form the test set, every clip of
  another content the training set. Motion the methods never saw.
- ``heldout-actions``: as ``heldout-contents``, one fold per content of
  :data:`HELDOUT_ACTIONS` present (everyday motion that is not walking: the Bandai-Namco action
  folders), trained on every clip of another content, walking included. Meant for the
  locomotion and action folders together (``--data`` of all four Bandai-Namco folders).
- ``cross-dataset``: train on some folders, test on another (other people, another rig); the
  bench gets the two sets separately and compares canonical body parts
  (:func:`imuloco.measures.metrics.evaluate_parts`).

Version 2 added ``heldout-contents`` and ``cross-dataset`` (and later ``heldout-actions``, which
changes no other protocol's split); ``random-clips`` and ``heldout-styles`` split as in version 1,
so their numbers compare across the two versions.

Test recordings are simulated with seeds offset by
:data:`imuloco.methods.training.TEST_SEED_OFFSET`, never shared with training.
"""

from __future__ import annotations

import zlib

from imuloco.core.motion import MotionDatabase
from imuloco.errors import InputError, UnknownNameError

PROTOCOL_VERSION = 2
SPLITS = ("random-clips", "heldout-styles", "heldout-contents", "cross-dataset",
          "heldout-actions")
HELDOUT_CONTENTS = ("walk", "walk-turn-left", "walk-turn-right", "run", "dash", "walk-back",
                    "walk-left", "walk-right")
# the contents of bandai-namco-1-actions and bandai-namco-2-actions (../shared/data/README.md)
HELDOUT_ACTIONS = ("bow", "bye", "byebye", "guide", "call", "dance-short", "kick", "punch",
                   "respond", "slash", "raise-up-both-hands", "raise-up-left-hand",
                   "raise-up-right-hand", "wave-both-hands", "wave-left-hand", "wave-right-hand")
MOTION_TYPES = HELDOUT_CONTENTS + HELDOUT_ACTIONS
# the protocols with one fold per left-out content, and the contents they leave out
LEAVE_CONTENT_OUT = {"heldout-contents": HELDOUT_CONTENTS, "heldout-actions": HELDOUT_ACTIONS}
HELDOUT_STYLES = ("exhausted", "feminine")
TEST_FRACTION = 0.2


def in_random_test(name: str) -> bool:
    """Whether a clip (by file name, without folder) is in the ``random-clips`` test set."""
    return zlib.crc32(name.encode()) < TEST_FRACTION * 2**32


def folds(db: MotionDatabase, name: str) -> list[tuple[str, MotionDatabase, MotionDatabase]]:
    """``(fold, train, test)`` of protocol ``name``: one fold named ``"all"`` for a split,
    one per left-out content for ``heldout-contents`` and ``heldout-actions``."""
    if name not in LEAVE_CONTENT_OUT:
        return [("all", *split(db, name))]
    contents = LEAVE_CONTENT_OUT[name]
    present = {lab.get("content") for lab in db.labels}
    out = []
    for content in [c for c in contents if c in present]:
        test = [lab.get("content") == content for lab in db.labels]
        out.append((content, db.subset([i for i, t in enumerate(test) if not t]),
                    db.subset([i for i, t in enumerate(test) if t])))
    if not out or any(not len(train) for _, train, _ in out):
        raise InputError(f"{name} needs clips of one of the contents {list(contents)} and "
                         f"of another content to train on; the data has "
                         f"{sorted(present - {None})}")
    return out


def split(db: MotionDatabase, name: str) -> tuple[MotionDatabase, MotionDatabase]:
    """Training and test databases of split ``name`` (``random-clips`` or
    ``heldout-styles``)."""
    if name == "random-clips":
        test = [in_random_test(lab["name"]) for lab in db.labels]
    elif name == "heldout-styles":
        test = [lab.get("style") in HELDOUT_STYLES for lab in db.labels]
    else:
        raise UnknownNameError(f"unknown split {name!r} here; splits: {list(SPLITS[:2])} "
                               "(heldout-contents has folds, cross-dataset its own test data)")
    train_idx = [i for i, t in enumerate(test) if not t]
    test_idx = [i for i, t in enumerate(test) if t]
    if not train_idx or not test_idx:
        raise InputError(f"split {name!r} leaves an empty training or test set "
                         f"({len(train_idx)} / {len(test_idx)} clips): give more clips "
                         "(--limit) or data of more styles")
    return db.subset(train_idx), db.subset(test_idx)
