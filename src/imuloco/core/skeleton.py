"""Skeleton: joint names, parent indices and rest offsets (metres)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from imuloco.core.bodymap import BodyMap, resolve_body_map
from imuloco.errors import UnknownNameError


@dataclass(frozen=True, eq=False)
class Skeleton:
    """A kinematic tree.

    Attributes
    ----------
    names : list of str, length J
    parents : ndarray, shape (J,), int; ``-1`` for the root, and ``parents[j] < j``.
    offsets : ndarray, shape (J, 3), metres: joint ``j``'s position in its parent's frame at rest.
    end_sites : dict mapping a joint index to its End Site offset (metres), for BVH writing.
    body_map : the joint name that stands for each canonical body part
        (see :mod:`imuloco.core.bodymap`); resolved from the names when not given.
    """

    names: list[str]
    parents: np.ndarray
    offsets: np.ndarray
    end_sites: dict[int, np.ndarray] = field(default_factory=dict)
    body_map: BodyMap | None = None

    def __post_init__(self) -> None:
        parents = np.asarray(self.parents, dtype=np.int64)
        offsets = np.asarray(self.offsets, dtype=np.float64)
        n = len(self.names)
        if parents.shape != (n,) or offsets.shape != (n, 3):
            raise ValueError(
                f"skeleton: expected parents (J,) and offsets (J, 3) for J={n} names, "
                f"got {parents.shape} and {offsets.shape}"
            )
        if n and (parents[0] != -1 or (parents[1:] >= np.arange(1, n)).any()
                  or (parents[1:] < 0).any()):
            raise ValueError("skeleton: parents must be -1 for joint 0 and precede each child")
        object.__setattr__(self, "parents", parents)
        object.__setattr__(self, "offsets", offsets)
        if self.body_map is None:
            object.__setattr__(self, "body_map", resolve_body_map(self.names, strict=False))

    @property
    def num_joints(self) -> int:
        return len(self.names)

    def index(self, name: str) -> int:
        """Index of a joint by its name."""
        try:
            return self.names.index(name)
        except ValueError:
            raise UnknownNameError(f"skeleton has no joint named {name!r}; joints: {self.names}") from None

    def part(self, part: str) -> int:
        """Index of the joint that stands for a canonical body part such as ``"right_knee"``."""
        assert self.body_map is not None
        if part not in self.body_map:
            raise UnknownNameError(
                f"body part {part!r} is not mapped on this skeleton; mapped parts: "
                f"{sorted(self.body_map)}. Give a map with imuloco.core.bodymap.resolve_body_map."
            )
        return self.index(self.body_map[part])

    def children(self, j: int) -> list[int]:
        return [int(c) for c in np.flatnonzero(self.parents == j)]

    def scaled(self, factor: float) -> Skeleton:
        """The same tree with offsets (and End Sites) multiplied by ``factor``."""
        return Skeleton(
            list(self.names), self.parents.copy(), self.offsets * factor,
            {k: v * factor for k, v in self.end_sites.items()}, dict(self.body_map or {}),
        )

    def leg_length(self) -> float:
        """Hip-to-ankle length of the right leg (metres), a scale for adaptive thresholds."""
        length = 0.0
        j = self.part("right_ankle")
        hip = self.part("right_hip")
        while j != hip and j > 0:
            length += float(np.linalg.norm(self.offsets[j]))
            j = int(self.parents[j])
        return length
