"""The interface every reconstruction method implements.

A method is an estimator: ``__init__`` stores hyperparameters, :meth:`Method.fit` synthesizes
sensor signals for a MotionDatabase and learns, :meth:`Method.reconstruct` turns a Recording
into a Motion, and :meth:`Method.stream` (for online methods) takes one sensor frame at a time.
Signals reach a method at its model rate (the training motion's frame rate) as rows of
``6 S`` channels (per sensor acc x,y,z then gyro x,y,z), see :mod:`imuloco.methods.training`.

A new method is one module with one subclass, named in the ``imuloco.methods`` entry-point
group (:mod:`imuloco.methods.registry`); it is then available to ``bench``, ``train``,
``reconstruct`` and ``live``. Fitted methods are saved by :mod:`imuloco.methods.modelfile`.
"""

from __future__ import annotations

import datetime
import inspect
import os
import platform
import time
from abc import ABC, abstractmethod
from collections.abc import Sequence
from pathlib import Path
from typing import Any, ClassVar, Self

import numpy as np

from imuloco.core.motion import Motion, MotionDatabase
from imuloco.core.recording import Recording
from imuloco.methods.training import Example, synthesize, to_frames


class Stream(ABC):
    """Online reconstruction: one sensor frame in, one pose out, causal, bounded state.

    ``delay_frames``: how many frames the returned pose lags the sample just read (a model
    with look-ahead returns frame t - delay_frames after reading frame t)."""

    delay_frames: int = 0

    def delay_ms(self, fps: float) -> float:
        """``delay_frames`` in milliseconds at ``fps`` frames per second."""
        return 1e3 * self.delay_frames / fps

    @abstractmethod
    def step(self, sample: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """sample : (6 S,) one frame of signals -> (local rotations (J, 4), root (3,))."""


class Method(ABC):
    """Base class of reconstruction methods (see the module docstring)."""

    name: ClassVar[str]
    summary: ClassVar[str]  # one line for ``imuloco methods``
    supports_online: ClassVar[bool] = False
    # hyperparameters added after model files were written, with the value that reproduces
    # those files' behaviour (not the new default) when their header lacks them
    legacy_params: ClassVar[dict[str, Any]] = {}
    # hyperparameters removed from the method, with the one value the current code reproduces
    # (None: any, it no longer matters): old files that carry it load without it, files with
    # another value are refused (retrain them)
    retired_params: ClassVar[dict[str, Any]] = {}

    # ---- learning ---------------------------------------------------------------------------
    def fit(self, db: MotionDatabase, placements: Sequence[str] = ("right_ankle",),
            noise: str = "phone", seed: int = 0, progress: bool = False) -> Self:
        """Synthesize ``placements`` with ``noise`` on ``db`` and learn from it.

        Records what it was trained on in ``protocol_`` (saved with the model): clips, frames,
        placements, noise, seed, seconds, date and machine; callers may add to it (the
        ``train`` command adds the data folder and split)."""
        if len(db) == 0:
            raise ValueError("cannot fit on an empty database")
        self.placements_ = list(placements)
        self.noise_ = noise
        self.skeleton_ = db.skeleton
        self.fps_ = float(db.clips[0].fps)
        start = time.perf_counter()
        self.fit_examples(synthesize(db, placements, noise, seed, progress=progress),
                          progress=progress)
        self.protocol_ = {
            "clips": len(db), "frames": int(db.num_frames), "placements": list(placements),
            "noise": noise, "seed": seed,
            "train_seconds": round(time.perf_counter() - start, 1),
            "trained_at": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
            "machine": f"{platform.machine()}, {os.cpu_count()} CPUs",
        }
        return self

    @abstractmethod
    def fit_examples(self, examples: list[Example], progress: bool = False) -> None:
        """Learn from clips with their signals at the model rate."""

    # ---- reconstruction ---------------------------------------------------------------------
    def reconstruct(self, rec: Recording) -> Motion:
        """Reconstruct a Motion at the model rate from a recording of the fitted placements."""
        rec = rec.select(self.placements_)
        frames = round((rec.times[-1] - rec.times[0]) * self.fps_) + 1
        times = np.arange(frames) / self.fps_
        return self.reconstruct_signals(to_frames(rec, times, self.fps_))

    @abstractmethod
    def reconstruct_signals(self, signals: np.ndarray) -> Motion:
        """signals : (T, 6 S) at the model rate -> Motion of T frames on ``skeleton_``."""

    def stream(self) -> Stream:
        """A fresh online reconstruction session (online methods only)."""
        raise NotImplementedError(f"method {self.name!r} has no online mode")

    # ---- persistence ------------------------------------------------------------------------
    @abstractmethod
    def get_state(self) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Learned arrays and JSON-able learned values (besides placements, fps, skeleton)."""

    @abstractmethod
    def set_state(self, arrays: dict[str, np.ndarray], values: dict[str, Any]) -> None:
        """Restore what :meth:`get_state` returned."""

    def get_params(self) -> dict[str, Any]:
        """Hyperparameters: the ``__init__`` arguments, read back from attributes."""
        sig = inspect.signature(type(self).__init__)
        return {k: getattr(self, k) for k in sig.parameters if k != "self"}

    def write_training_report(self, model_path: str | Path) -> list[Path]:
        """Write what the last fit recorded beside ``model_path`` (loss curves and the like)
        and return the files written; methods without a training history write nothing."""
        return []

    def save(self, path: str | Path, overwrite: bool = False) -> Path:
        """Write the fitted model to one ``.npz`` file (:mod:`imuloco.methods.modelfile`)."""
        from imuloco.methods.modelfile import save_model

        return save_model(self, path, overwrite=overwrite)
