"""The body's path (issue 40): :class:`BodyPath` and one estimator per sensor placement."""

from imuloco.paths.base import BodyPath, Footfall, PathEstimator, Stride

__all__ = ["BodyPath", "Footfall", "PathEstimator", "Stride"]
