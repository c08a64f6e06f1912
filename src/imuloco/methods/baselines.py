"""Floors every method must beat: the mean pose, and (later) ridge and kNN regressions."""

from __future__ import annotations

from typing import Any

import numpy as np

from imuloco.core.motion import Motion
from imuloco.methods import pose
from imuloco.methods.base import Method, Stream, register
from imuloco.methods.training import Example


class _ConstantStream(Stream):
    def __init__(self, motion: Motion) -> None:
        self.rot, self.root = motion.rotations[0], motion.root[0]

    def step(self, sample: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.rot, self.root


@register
class MeanPose(Method):
    """The mean pose vector of the training data, whatever the sensors read (a standing
    figure that walks at the mean speed)."""

    name = "mean"
    summary = "mean training pose, ignores the sensors (a floor for every metric)"
    supports_online = True

    def __init__(self) -> None:
        pass

    def fit_examples(self, examples: list[Example], progress: bool = False) -> None:
        self.mean_ = np.concatenate([pose.encode(e.motion) for e in examples]).mean(axis=0)

    def reconstruct_signals(self, signals: np.ndarray) -> Motion:
        return pose.decode(np.tile(self.mean_, (len(signals), 1)), self.skeleton_, self.fps_)

    def stream(self) -> Stream:
        return _ConstantStream(self.reconstruct_signals(np.zeros((1, 6 * len(self.placements_)))))

    def get_state(self) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        return {"mean": self.mean_}, {}

    def set_state(self, arrays: dict[str, np.ndarray], values: dict[str, Any]) -> None:
        self.mean_ = arrays["mean"]
