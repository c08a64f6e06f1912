"""Motion (one clip) and MotionDatabase (labelled clips)."""

from __future__ import annotations

from collections.abc import Callable, Hashable, Iterator
from dataclasses import dataclass, field
from hashlib import blake2b
from typing import TypeVar

import numpy as np

from imuloco.core.skeleton import Skeleton
from imuloco.ops.kinematics import fk
from imuloco.ops.rotations import normalize

_T = TypeVar("_T")


@dataclass(eq=False)
class Motion:
    """A skeleton animation.

    Attributes
    ----------
    skeleton : Skeleton
    rotations : ndarray, shape (T, J, 4), local joint rotations, quaternions x, y, z, w.
    root : ndarray, shape (T, 3), world position of joint 0 in metres (Y up).
    fps : frames per second.
    name : a label for messages and reports (usually the file stem).
    """

    skeleton: Skeleton
    rotations: np.ndarray
    root: np.ndarray
    fps: float
    name: str = ""

    def __post_init__(self) -> None:
        self.rotations = np.asarray(self.rotations, dtype=np.float64)
        self.root = np.asarray(self.root, dtype=np.float64)
        t = len(self.rotations) if self.rotations.ndim else 0
        if self.rotations.shape != (t, self.skeleton.num_joints, 4) or self.root.shape != (t, 3):
            raise ValueError(
                f"motion {self.name!r}: expected rotations (T, {self.skeleton.num_joints}, 4) "
                f"and root (T, 3), got {self.rotations.shape} and {self.root.shape}"
            )
        if not (np.isfinite(self.rotations).all() and np.isfinite(self.root).all()):
            raise ValueError(f"motion {self.name!r}: rotations or root contain NaN or inf")

    @property
    def num_frames(self) -> int:
        return self.rotations.shape[0]

    @property
    def duration(self) -> float:
        """Seconds from the first to the last frame."""
        return (self.num_frames - 1) / self.fps

    @property
    def times(self) -> np.ndarray:
        """Frame times in seconds, shape (T,)."""
        return np.arange(self.num_frames) / self.fps

    def fk(self) -> tuple[np.ndarray, np.ndarray]:
        """Global rotations (T, J, 4) and positions (T, J, 3), metres (read-only arrays).

        Computed once per motion and kept (:meth:`kept`): one reconstruction's report, gait,
        checks, path and pinning all read them (they asked fifteen times on a 640 s walk,
        3.4 s)."""
        def compute() -> tuple[np.ndarray, np.ndarray]:
            glob, pos = fk(normalize(self.rotations), self.root, self.skeleton.offsets,
                           self.skeleton.parents)
            glob.flags.writeable = pos.flags.writeable = False  # shared by every caller
            return glob, pos

        return self.kept("fk", compute)

    def kept(self, name: Hashable, compute: Callable[[], _T]) -> _T:
        """``compute()``, computed once and kept on this motion under ``name`` (what is
        derived from its poses: world positions, contacts). A kept value is used while
        ``rotations``, ``root`` and the skeleton are the same arrays with the same contents
        (a digest of their bytes, ~1/20 of an fk's cost), so a caller who changes them in
        place gets it computed again. Keep read-only arrays only: every caller shares them."""
        key = self._fk_key()
        cache = self.__dict__.setdefault("_kept", {})
        if cache.get(name, (None,))[0] != key:
            cache[name] = (key, compute())
        return cache[name][1]

    def __getstate__(self) -> dict:
        """Pickled (a batch's workers, copies) without what :meth:`kept` holds."""
        return {k: v for k, v in self.__dict__.items() if k != "_kept"}

    def _fk_key(self) -> tuple:
        """What the kept fk depends on: the arrays' identities and a digest of their bytes."""
        arrays = (self.rotations, self.root, self.skeleton.offsets, self.skeleton.parents)
        digest = blake2b(digest_size=16)
        for a in arrays:
            digest.update(np.ascontiguousarray(a).data)
        return tuple(id(a) for a in arrays) + (digest.digest(),)

    def positions(self) -> np.ndarray:
        """World joint positions, shape (T, J, 3), metres (read-only: :meth:`fk`'s, kept)."""
        return self.fk()[1]

    def part_positions(self, parts: list[str]) -> np.ndarray:
        """World positions of canonical body parts, shape (T, len(parts), 3)."""
        idx = [self.skeleton.part(p) for p in parts]
        return self.positions()[:, idx]

    def slice(self, start: int, stop: int) -> Motion:
        """Frames ``start:stop`` as a new Motion."""
        return Motion(self.skeleton, self.rotations[start:stop].copy(),
                      self.root[start:stop].copy(), self.fps, self.name)

    def copy(self) -> Motion:
        return self.slice(0, self.num_frames)


@dataclass(eq=False)
class MotionDatabase:
    """Labelled clips that share one skeleton.

    ``labels[i]`` is a dict with at least ``name`` and, where known, ``content`` (motion type
    such as ``"walk"``, ``"walk-turn-left"``, ``"walk-turn-right"``, ``"run"``) and ``style``.
    """

    clips: list[Motion]
    labels: list[dict[str, str]] = field(default_factory=list)

    def __post_init__(self) -> None:
        if not self.labels:
            self.labels = [{"name": c.name} for c in self.clips]
        if len(self.labels) != len(self.clips):
            raise ValueError("database: one label dict per clip is required")

    def __len__(self) -> int:
        return len(self.clips)

    def __iter__(self) -> Iterator[tuple[Motion, dict[str, str]]]:
        return iter(zip(self.clips, self.labels))

    @property
    def skeleton(self) -> Skeleton:
        if not self.clips:
            raise ValueError("database is empty")
        return self.clips[0].skeleton

    @property
    def num_frames(self) -> int:
        return sum(c.num_frames for c in self.clips)

    def subset(self, indices: list[int] | np.ndarray) -> MotionDatabase:
        return MotionDatabase([self.clips[i] for i in indices], [self.labels[i] for i in indices])

    def where(self, **match: str | list[str]) -> MotionDatabase:
        """Clips whose labels match, e.g. ``db.where(content="walk")`` or
        ``db.where(style=["exhausted", "feminine"])``."""
        def ok(lab: dict[str, str]) -> bool:
            return all(lab.get(k) in (v if isinstance(v, list) else [v]) for k, v in match.items())
        return self.subset([i for i, lab in enumerate(self.labels) if ok(lab)])
