"""The interface every reconstruction method implements.

A method is an estimator in scikit-learn's manner: ``__init__`` stores hyperparameters
(:meth:`Method.get_params` / :meth:`Method.set_params` read and change them), learned state ends
with an underscore and exists only after fitting (reading it before raises
:class:`~imuloco.errors.NotFittedError`).

- :meth:`Method.fit` synthesizes sensor signals for a MotionDatabase (a
  :class:`~imuloco.methods.training.TrainingSet`) and calls :meth:`Method.fit_set`;
- :meth:`Method.fit_set` calls the method's learning step :meth:`Method.learn` with that one
  explicit input, then records what the method was fitted on (``skeleton_``, ``fps_``,
  ``placements_``, ``noise_``, ``protocol_``);
- :meth:`Method.reconstruct` turns a Recording into a Motion, :meth:`Method.reconstruct_full`
  into a :class:`Reconstruction` (the motion with the method's per-frame confidence, for methods
  that give one), :meth:`Method.stream` (online methods) takes one sensor frame at a time; :attr:`Method.pins_feet` says whether the method
  pins its own feet (then the pipeline does not).

Signals reach a method at its model rate (the training motion's frame rate) as rows of
``6 S`` channels (per sensor acc x,y,z then gyro x,y,z), see :mod:`imuloco.methods.training`.

A new method is one module with one subclass, named in the ``imuloco.methods`` entry-point
group (:mod:`imuloco.methods.registry`); it is then available to ``bench``, ``train``,
``reconstruct`` and ``live``. Fitted methods are saved by :mod:`imuloco.methods.modelfile`.
"""

from __future__ import annotations

import datetime
import inspect
import math
import os
import platform
import time
from abc import ABC, ABCMeta, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Self

import numpy as np

from imuloco.core.motion import Motion, MotionDatabase
from imuloco.core.recording import Recording
from imuloco.core.skeleton import Skeleton
from imuloco.errors import InputError, NotFittedError, UnknownNameError
from imuloco.methods.modelfile import save_model
from imuloco.methods.names import registered_name
from imuloco.methods.params import Constraint, bind, check_params
from imuloco.methods.training import TrainingSet, model_frames


@dataclass
class Reconstruction:
    """A reconstructed motion and, for methods that give one, its per-frame confidence.

    motion : the Motion (T frames).
    error_m : ndarray, shape (T,), or None: the predicted rms joint position error of each
        frame in metres (root-relative; lower is more confident), calibrated on data the model
        did not train on where the model file says so (see ``note``).
    unreliable : ndarray of bool, shape (T,), or None: frames flagged because the method does
        not know the motion (see ``note`` for how the flag is set).
    note : how ``error_m`` was calibrated and the flag set (one sentence for reports).
    scores : the uncalibrated per-frame quantities (T,) ``error_m`` is calibrated from, by name
        (what :mod:`imuloco.lab.confidence` fits a calibration on).
    """

    motion: Motion
    error_m: np.ndarray | None = None
    unreliable: np.ndarray | None = None
    note: str | None = None
    scores: dict[str, np.ndarray] | None = None


def calibrated_error(calibration: dict[str, Any], scores: dict[str, np.ndarray]) -> np.ndarray:
    """Predicted error (T,) in metres from a method's per-frame ``scores`` (T,) by name under
    a ``calibration`` ``{"coef": [a, b_1, ...], "scores": [name_1, ...]}``:
    ``exp(a) * prod_k scores[name_k] ** b_k`` (fitted by :func:`imuloco.lab.confidence.
    fit`)."""
    coef = calibration["coef"]
    out = np.full(len(next(iter(scores.values()))), np.exp(coef[0]))
    for b, name in zip(coef[1:], calibration["scores"]):
        out = out * np.maximum(np.asarray(scores[name], float), 1e-6) ** b
    return out


class Stream(ABC):
    """Online reconstruction: one sensor frame in, one pose out, causal, bounded state.

    ``delay_frames``: how many frames the returned pose lags the sample just read (a model
    with look-ahead returns frame t - delay_frames after reading frame t). After each step,
    ``error_m`` (metres, NaN when the method gives no confidence) and ``unreliable`` hold the
    returned frame's confidence as in :class:`Reconstruction`."""

    delay_frames: int = 0
    error_m: float = float("nan")
    unreliable: bool = False
    novelty: float | None = None  # the novelty of the frame read (Method.novelty_threshold)

    def delay_ms(self, fps: float) -> float:
        """``delay_frames`` in milliseconds at ``fps`` frames per second."""
        return 1e3 * self.delay_frames / fps

    @abstractmethod
    def step(self, sample: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """sample : (6 S,) one frame of signals -> (local rotations (J, 4), root (3,))."""


class _RegisteredName:
    """A method class's name: its entry point's in the group ``imuloco.methods`` (stated once,
    in ``pyproject.toml``; :func:`imuloco.methods.names.registered_name`). A class
    registered by hand states ``name`` itself, which takes precedence."""

    def __get__(self, obj: object, cls: type) -> str:
        return registered_name(cls)


class _Checked(ABCMeta):
    """Method classes' type: a method's hyperparameters pass its constraint table
    (:func:`imuloco.methods.params.check_params`) before its ``__init__`` stores them."""

    def __call__(cls, *args: Any, **kwargs: Any) -> Any:
        name = getattr(cls, "name", cls.__name__)
        params = bind(cls, name, args, kwargs)
        check_params(cls, name, params)
        method = super().__call__(*args, **kwargs)
        method.check_together()
        return method


class Method(ABC, metaclass=_Checked):
    """Base class of reconstruction methods (see the module docstring)."""

    name: ClassVar[str] = _RegisteredName()  # type: ignore[assignment]
    summary: ClassVar[str]  # one line for ``imuloco methods``
    supports_online: ClassVar[bool] = False
    # frames inside a gap of a recording reach reconstruct_signals as rows of NaN (methods
    # that model missing samples) instead of interpolated
    gaps_missing: ClassVar[bool] = False
    # hyperparameters added after model files were written, with the value that reproduces
    # those files' behaviour (not the new default) when their header lacks them
    legacy_params: ClassVar[dict[str, Any]] = {}
    # hyperparameters that change only the online stream (read when a stream starts), not what
    # fit learns: a fitted model serves every value of them (the speed bench times them on one)
    stream_params: ClassVar[tuple[str, ...]] = ()
    # hyperparameters removed from the method, with the one value the current code reproduces
    # (None: any, it no longer matters): old files that carry it load without it, files with
    # another value are refused (retrain them)
    retired_params: ClassVar[dict[str, Any]] = {}
    # the method's constraint table (imuloco.methods.params): the values a fit can use of a
    # numeric hyperparameter, as an interval ("[1, inf)", "(0, 1]"; of a list-valued one, of
    # each of its at least one items), or the Options of a string one; the kinds come from the
    # signature. Checked at construction, fit and load, so that a window of 0 is refused by
    # name, not by numpy deep in a fit
    param_constraints: ClassVar[dict[str, Constraint]] = {}

    @property
    def pins_feet(self) -> bool:
        """Whether :meth:`reconstruct` pins the feet during their contacts itself (with
        contacts it predicts); the pipeline then does not pin them again."""
        return False

    @property
    def novelty_threshold(self) -> float | None:
        """The novelty score (``scores["novelty"]`` of :meth:`reconstruct_signals_full`, a
        stream's ``novelty``) over which the method flags a frame as motion it does not know,
        on its own scale (what :mod:`imuloco.methods.fallback` judges novelty against);
        ``None``: the method gives no novelty."""
        return None

    # ---- learning ---------------------------------------------------------------------------
    def fit(self, db: MotionDatabase, placements: Sequence[str] = ("right_ankle",),
            noise: str = "phone", seed: int = 0, progress: bool = False) -> Self:
        """Synthesize ``placements`` with ``noise`` on ``db`` and learn from it
        (:meth:`TrainingSet.synthesize <imuloco.methods.training.TrainingSet.synthesize>`
        then :meth:`fit_set`).

        Records what it was trained on in ``protocol_`` (saved with the model): clips, frames,
        placements, noise, seed, seconds (simulation included), date and machine; callers may
        add to it (the ``train`` command adds the data folder and split)."""
        start = time.perf_counter()
        self.fit_set(TrainingSet.synthesize(db, placements, noise, seed, progress=progress),
                     progress=progress)
        self.protocol_["train_seconds"] = round(time.perf_counter() - start, 1)
        return self

    def fit_set(self, data: TrainingSet, progress: bool = False) -> Self:
        """Learn from an already synthesized :class:`~imuloco.methods.training.TrainingSet`
        (:meth:`learn`) and record what the method was fitted on."""
        self.check_params()
        start = time.perf_counter()
        self.learn(data, progress=progress)
        self.set_setup(data.skeleton, data.fps, data.placements, data.noise)
        self.protocol_ = {
            "clips": len(data.examples), "frames": int(data.num_frames),
            "placements": list(data.placements), "noise": data.noise, "seed": data.seed,
            "train_seconds": round(time.perf_counter() - start, 1),
            "trained_at": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
            "machine": f"{platform.machine()}, {os.cpu_count()} CPUs",
        }
        return self

    @abstractmethod
    def learn(self, data: TrainingSet, progress: bool = False) -> None:
        """The learning step: set the learned state from ``data`` alone (its clips, skeleton,
        rate, placements and noise); called by :meth:`fit_set`, which records the setup
        after it."""

    def set_setup(self, skeleton: Skeleton, fps: float, placements: Sequence[str],
                  noise: str) -> None:
        """Record what the method reads and writes: the output ``skeleton_`` at ``fps_``
        frames per second, from signals of ``placements_`` simulated with ``noise_`` (set by
        :meth:`fit_set` and by :func:`~imuloco.methods.modelfile.load_model`)."""
        self.skeleton_ = skeleton
        self.fps_ = float(fps)
        self.placements_ = list(placements)
        self.noise_ = noise

    def __getattr__(self, attr: str) -> Any:
        # only called for attributes that do not exist: a learned one (trailing underscore)
        # that does not exist yet means the method was not fitted
        if attr.endswith("_") and not attr.startswith("__"):
            raise NotFittedError(
                f"method {getattr(type(self), 'name', type(self).__name__)!r} is not fitted "
                f"yet (no {attr}): call fit() or load a model file (imuloco.methods.load_model)")
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {attr!r}")

    def check_fitted(self) -> None:
        """Raise :class:`~imuloco.errors.NotFittedError` unless the method was fitted."""
        self.placements_  # noqa: B018  (raises through __getattr__)

    # ---- reconstruction ---------------------------------------------------------------------
    def reconstruct(self, rec: Recording) -> Motion:
        """Reconstruct a Motion at the model rate from a recording of the fitted placements
        (its signals on the model-rate grid, :func:`imuloco.methods.training.model_frames`)."""
        rec = rec.select(self.placements_)
        return self.reconstruct_signals(model_frames(rec, self.fps_, self.gaps_missing))

    @abstractmethod
    def reconstruct_signals(self, signals: np.ndarray) -> Motion:
        """signals : (T, 6 S) at the model rate -> Motion of T frames on ``skeleton_``."""

    def reconstruct_full(self, rec: Recording) -> Reconstruction:
        """:meth:`reconstruct` with the method's per-frame confidence where it gives one."""
        rec = rec.select(self.placements_)
        return self.reconstruct_signals_full(model_frames(rec, self.fps_, self.gaps_missing))

    def reconstruct_signals_full(self, signals: np.ndarray) -> Reconstruction:
        """:meth:`reconstruct_signals` as a :class:`Reconstruction`; methods with a confidence
        override this (the default gives none)."""
        return Reconstruction(self.reconstruct_signals(signals))

    def set_calibration(self, calibration: dict[str, Any]) -> None:
        """Use ``calibration`` (:func:`imuloco.lab.confidence.fit`) for ``error_m`` from
        now on (saved with the model); methods that predict no error refuse it."""
        raise InputError(f"method {self.name!r} predicts no per-frame error to calibrate")

    def can_stream(self) -> bool:
        """Whether this instance reconstructs online (:meth:`stream`): its class's
        ``supports_online``, unless a hyperparameter rules it out."""
        return self.supports_online

    def stream(self) -> Stream:
        """A fresh online reconstruction session (online methods only)."""
        raise NotImplementedError(f"method {self.name!r} has no online mode")

    # ---- hyperparameters (scikit-learn's estimator conventions) -----------------------------
    @classmethod
    def _param_names(cls) -> list[str]:
        sig = inspect.signature(cls.__init__)
        return [k for k, p in sig.parameters.items()
                if k != "self" and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)]

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        """Hyperparameters: the ``__init__`` arguments, read back from attributes (``deep`` is
        accepted for scikit-learn's ``clone``; methods hold no nested estimators)."""
        return {k: getattr(self, k) for k in self._param_names()}

    def set_params(self, **params: Any) -> Self:
        """Change hyperparameters (refit afterwards); unknown names raise
        :class:`~imuloco.errors.UnknownNameError`."""
        valid = self._param_names()
        for key, value in params.items():
            if key not in valid:
                raise UnknownNameError(f"method {self.name!r} has no hyperparameter {key!r}; "
                                       f"it has {valid}")
            setattr(self, key, value)
        return self

    def check_params(self) -> None:
        """Raise :class:`~imuloco.errors.ParameterError` (an InputError) naming the first
        hyperparameter its constraint table refuses (:func:`imuloco.methods.params.
        check_params`), then :meth:`check_together`."""
        check_params(type(self), self.name, self.get_params())
        self.check_together()

    def check_together(self) -> None:
        """Raise :class:`~imuloco.errors.ParameterError` for hyperparameters that each pass
        the table but not together; none by default."""

    def __repr__(self) -> str:
        """``Class(param=value, ...)`` with the hyperparameters that differ from the
        defaults, as scikit-learn prints estimators."""
        sig = inspect.signature(type(self).__init__)
        changed = [f"{k}={v!r}" for k, v in self.get_params().items()
                   if not _same(v, sig.parameters[k].default)]
        return f"{type(self).__name__}({', '.join(changed)})"

    # ---- persistence ------------------------------------------------------------------------
    @abstractmethod
    def get_state(self) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Learned arrays and JSON-able learned values (besides placements, fps, skeleton)."""

    @abstractmethod
    def set_state(self, arrays: dict[str, np.ndarray], values: dict[str, Any]) -> None:
        """Restore what :meth:`get_state` returned."""

    def write_training_report(self, model_path: str | Path) -> list[Path]:
        """Write what the last fit recorded beside ``model_path`` (loss curves and the like)
        and return the files written; methods without a training history write nothing."""
        return []

    def save(self, path: str | Path, overwrite: bool = False) -> Path:
        """Write the fitted model to one ``.npz`` file (:mod:`imuloco.methods.modelfile`)."""
        self.check_fitted()
        return save_model(self, path, overwrite=overwrite)


def _same(a: Any, b: Any) -> bool:
    """Equal hyperparameter values (NaN equals NaN; a tuple equals the same list)."""
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return list(a) == list(b)
    try:
        return bool(a == b)
    except (TypeError, ValueError):
        return a is b
