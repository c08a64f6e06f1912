"""Tautges, Krüger, Zinke and Weber 2008: reconstruction with a multilinear motion model.

Choices where the paper is silent (each also noted where it is made):

- Tensors hold gait cycles (right strike to right strike, :mod:`imuloco.phases`) warped
  linearly to ``frames + 1`` samples; one tensor pair per content label (walk,
  walk-turn-left, walk-turn-right, run). Natural modes are style x repetition: the data names
  no actor. ``repetitions`` cycles per style are taken evenly spaced from all of that style's
  cycles (the paper's tensor had 3 repetitions).
- A window of the recording rarely starts at a cycle's start, so besides x (eq. 4) each window
  optimizes the cycle phase at its first frame and the cycle period; the synthesized cycle is
  chained end to end over the window (:func:`~imuloco.methods.tautges2008.tensor.chain_cycles`).
  Each window starts from a grid of phases and periods at the mean x (or from the previous
  window's solution moved on by the hop, when better), then a trust-region least-squares
  solver refines them all (eq. 17 squared is a sum of squares). x stays within the range
  spanned by the data's rows, widened by ``bounds_margin`` (the paper gives no constraint).
- Cycles are closed into loops (the last pose's mismatch to the first spread over the cycle),
  so that chained cycles do not jump at heel strike.
- The motion type is chosen per recording (the paper assumes a known pre-classification): the
  tensor whose grid stage reaches the lowest eq. 17 distance summed over the windows.
- Accelerations: ``frame="world"`` (the paper's) compares free accelerations in a Y-up frame,
  estimated per sensor by the shared Madgwick filter (:mod:`imuloco.sensors.fusion`), under
  eq. 17's rotation about the vertical, one per sensor (no magnetometer: unrelated headings);
  ``frame="sensor"`` compares the raw sensor-frame specific force (gravity included), which
  needs no attitude filter and no rotation. Gyro signals are not used (the paper uses
  accelerations only).
- Windows overlap by half; their poses are blended with triangular weights as pose vectors
  (:mod:`imuloco.methods.pose`), which also chains their root paths.
"""

from __future__ import annotations

from collections import defaultdict
from typing import Any, ClassVar

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.optimize import least_squares

from imuloco.core.motion import Motion
from imuloco.errors import ParameterError
from imuloco.methods import pose
from imuloco.methods.base import Method
from imuloco.methods.params import Constraint, Options
from imuloco.methods.tautges2008.align import eq17_distance, world_acceleration
from imuloco.methods.tautges2008.tensor import (
    MotionModel,
    align_signs,
    build_model,
    chain_cycles,
    gait_cycles,
    register_cycle,
)
from imuloco.methods.training import TrainingSet
from imuloco.ops.rotations import about_y, qinv, qrot
from imuloco.sensors.placement import anatomical_frame, get_placement
from imuloco.sensors.simulate import GRAVITY, attached_trajectories

MARGIN = 3  # extra synthesized frames each side of a window, so the spline's ends do not count


class Tautges2008(Method):
    """Multilinear motion model reconstruction (Tautges et al. 2008, sec. 5.1).

    Parameters
    ----------
    frames : frame-mode size of the tensors, samples per registered cycle (sec. 2.2: 70 at
        120 Hz; ours are 30 fps clips, about 33 frames a walking cycle).
    repetitions : repetition-mode size (sec. 2.2: 3).
    style_rank, repetition_rank : truncation of the natural modes (sec. 5.1); None keeps all.
    window, hop : frames per optimization window and between window starts (sec. 5.1, not
        given in the paper: about one walking cycle, half overlap).
    phases, periods : start grid: cycle phases, and periods relative to the model's mean.
    max_iter : evaluations of the least-squares solver per window.
    bounds_margin : x's box is the rows' range widened by this fraction of it on each side.
    frame : ``"world"`` (eq. 17 on free accelerations) or ``"sensor"`` (see module docstring).
    """

    summary = "multilinear motion model fitted to windows of accelerations (Tautges 2008)"
    param_constraints: ClassVar[dict[str, Constraint]] = {
        # frames 1000 per cycle (the paper's 70 at 120 Hz; 1000 is over 8 s of a cycle at
        # 120 Hz), phases 360 (12; a start every degree of the cycle): beyond, memory ran out
        "frames": "[2, 1000]", "repetitions": "[1, inf)", "style_rank": "[1, inf)",
        "repetition_rank": "[1, inf)", "window": "[2, inf)", "hop": "[1, inf)",
        "phases": "[1, 360]", "periods": "(0, inf)", "max_iter": "[1, inf)",
        "bounds_margin": "[0, inf)", "frame": Options("world", "sensor")}

    def __init__(self, frames: int = 32, repetitions: int = 3, style_rank: int | None = None,
                 repetition_rank: int | None = None, window: int = 32, hop: int = 16,
                 phases: int = 12, periods: tuple[float, ...] = (0.8, 1.0, 1.25),
                 max_iter: int = 15, bounds_margin: float = 0.25, frame: str = "world") -> None:
        self.frames = frames
        self.repetitions = repetitions
        self.style_rank = style_rank
        self.repetition_rank = repetition_rank
        self.window = window
        self.hop = hop
        self.phases = phases
        self.periods = tuple(periods)  # a list after a JSON round trip
        self.max_iter = max_iter
        self.bounds_margin = bounds_margin
        self.frame = frame

    def check_together(self) -> None:
        if self.hop > self.window:  # frames between two windows would get no pose (NaN)
            raise ParameterError("hop", f"method {self.name!r}: hop must be at most window, "
                                        f"got hop {self.hop} > window {self.window}")

    # ---- learning ---------------------------------------------------------------------------
    def learn(self, data: TrainingSet, progress: bool = False) -> None:
        by_content: dict[str, dict[str, list]] = defaultdict(lambda: defaultdict(list))
        for ex in data.examples:
            for a, b in gait_cycles(ex.motion):
                rot, root = register_cycle(ex.motion, a, b, self.frames)
                by_content[ex.labels.get("content", "all")][ex.labels.get("style", "all")] \
                    .append((rot, root, b - a))
        self.models_: dict[str, MotionModel] = {}
        for content, styles in sorted(by_content.items()):
            r = min(self.repetitions, min(len(v) for v in styles.values()))
            picked = [[cyc[i] for i in np.linspace(0, len(cyc) - 1, r).round().astype(int)]
                      for _, cyc in sorted(styles.items())]
            rot = np.array([[c[0] for c in row] for row in picked])   # (d_s, d_r, F+1, J, 4)
            ref = rot[0, 0, 0]
            rot = align_signs(rot.reshape((-1,) + rot.shape[2:]), ref).reshape(rot.shape)
            root = np.array([[c[1] for c in row] for row in picked])
            period = np.array([[c[2] for c in row] for row in picked], dtype=float)
            self.models_[content] = build_model(rot, root, period, self.style_rank,
                                                self.repetition_rank)
        if not self.models_:
            raise ValueError("tautges2008: no complete gait cycle in the training clips")

    # ---- synthesis of candidate signals -----------------------------------------------------
    def _candidate_acc(self, model: MotionModel, p: np.ndarray, n: int
                       ) -> tuple[np.ndarray, Motion]:
        """Accelerations of candidates p (C, r_s + r_r + 2) over n frames -> (C, n, S, 3), and
        the candidates' motion with MARGIN frames each side (C (n + 2 MARGIN) frames)."""
        rs = model.rot_natural[0].shape[1]
        xs, xr = p[:, :rs], p[:, rs:-2]
        phase, period = p[:, -2], np.exp(p[:, -1])
        c, m = len(p), n + 2 * MARGIN
        u = 1.0 + phase[:, None] + (np.arange(m) - MARGIN)[None] / period[:, None]
        rot, root = chain_cycles(*model.synthesize(xs, xr), u)
        motion = Motion(self.skeleton_, rot.reshape(c * m, -1, 4), root.reshape(c * m, 3),
                        self.fps_)
        t = np.arange(m) / self.fps_
        pos, ori = attached_trajectories(motion, self._frames())
        acc = CubicSpline(t, pos.reshape(c, m, -1, 3), axis=1)(t[MARGIN:-MARGIN], 2)
        if self.frame == "sensor":
            q = ori.reshape(c, m, -1, 4)[:, MARGIN:-MARGIN]
            acc = qrot(qinv(q), acc - GRAVITY)
        return acc, motion

    def _frames(self) -> list[tuple[int, np.ndarray, np.ndarray]]:
        if getattr(self, "_anat", None) is None or self._anat[0] != self.placements_:
            self._anat = (list(self.placements_), [
                anatomical_frame(self.skeleton_, get_placement(p), self._poses())
                for p in self.placements_])
        return self._anat[1]

    def _poses(self) -> np.ndarray:
        """Poses (N, J, 4) that settle the sensors' twist on the segment, as
        :func:`~imuloco.sensors.simulate.sensor_trajectory` does with a motion's frames: the
        mean cycle of every motion type."""
        return np.concatenate([m.synthesize(*m.x_mean)[0] for m in self.models_.values()])

    def _residuals(self, model: MotionModel, p: np.ndarray, target: np.ndarray) -> np.ndarray:
        """Residuals (C, n S 3) of candidates p against a window ``target`` (n, S, 3), scaled
        so that their sum of squares is the window's mean squared eq. 17 distance."""
        acc, _ = self._candidate_acc(model, p, len(target))
        if self.frame == "world":
            theta = eq17_distance(target, acc)[1]                      # (C, S)
            acc = qrot(about_y(theta)[:, None, :, :], acc)
        return (target - acc).reshape(len(p), -1) / np.sqrt(target.shape[0] * target.shape[1])

    def _distance(self, model: MotionModel, p: np.ndarray, target: np.ndarray) -> np.ndarray:
        return np.sum(self._residuals(model, p, target) ** 2, axis=-1)

    def _grid(self, model: MotionModel) -> np.ndarray:
        xs, xr = model.x_mean
        base = float(np.log(model.period.mean()))
        ph = np.arange(self.phases) / self.phases
        per = base + np.log(np.asarray(self.periods, dtype=float))
        g = np.array([(a, b) for a in ph for b in per])
        return np.concatenate([np.tile(np.r_[xs, xr], (len(g), 1)), g], axis=1)

    def _bounds(self, model: MotionModel) -> list[tuple[float, float]]:
        lo = np.concatenate([u.min(0) for u in model.rot_natural])
        hi = np.concatenate([u.max(0) for u in model.rot_natural])
        wid = (hi - lo) * self.bounds_margin + 1e-3
        per = np.log(model.period.mean() * np.array([0.6, 1.6]))
        return list(zip(lo - wid, hi + wid)) + [(-0.5, 1.5), (per[0], per[1])]

    def _optimize(self, model: MotionModel, start: np.ndarray, target: np.ndarray
                  ) -> np.ndarray:
        """Minimize eq. 17 over x, phase and period from ``start``. The distance is a sum of
        squares, so a trust-region least-squares solver converges in a few Jacobians; each
        forward-difference Jacobian is one batch of candidates (one FK per sensor)."""
        h = 1e-4
        cache: dict[bytes, np.ndarray] = {}

        def fun(p: np.ndarray) -> np.ndarray:
            key = p.tobytes()
            if key not in cache:
                cache[key] = self._residuals(model, p[None], target)[0]
            return cache[key]

        def jac(p: np.ndarray) -> np.ndarray:
            batch = p + h * np.eye(len(p))
            return ((self._residuals(model, batch, target) - fun(p)) / h).T

        lo, hi = np.array(self._bounds(model)).T
        res = least_squares(fun, np.clip(start, lo + 1e-9, hi - 1e-9), jac=jac,
                            bounds=(lo, hi), method="trf", max_nfev=self.max_iter)
        return res.x

    # ---- reconstruction ---------------------------------------------------------------------
    def _targets(self, signals: np.ndarray) -> np.ndarray:
        if self.frame == "world":
            return world_acceleration(signals, self.fps_)
        s = signals.shape[1] // 6
        return signals.reshape(len(signals), s, 6)[:, :, :3]

    def _windows(self, t: int) -> list[int]:
        w = min(self.window, t)
        starts = list(range(0, t - w + 1, max(1, self.hop)))
        if starts[-1] != t - w:
            starts.append(t - w)
        return starts

    def reconstruct_signals(self, signals: np.ndarray) -> Motion:
        signals = np.asarray(signals, dtype=np.float64)
        t = len(signals)
        if t < 2:
            raise ValueError(f"tautges2008: need at least 2 frames of signals, got {t}")
        target = self._targets(signals)
        w = min(self.window, t)
        starts = self._windows(t)
        # motion type: lowest summed grid distance (the paper assumes it is known)
        scores, grids = {}, {}
        for content, model in self.models_.items():
            g = self._grid(model)
            d = np.array([self._distance(model, g, target[a:a + w]) for a in starts])
            scores[content], grids[content] = d.min(axis=1).sum(), (g, d)
        self.content_ = min(scores, key=scores.get)
        model = self.models_[self.content_]
        g, gd = grids[self.content_]
        acc_vec = np.zeros((t, pose.pose_dim(self.skeleton_)))
        acc_w = np.zeros(t)
        prev = None
        for k, a in enumerate(starts):
            start = g[np.argmin(gd[k])]
            if prev is not None:
                cand = prev.copy()
                cand[-2] = (cand[-2] + (a - starts[k - 1]) / np.exp(cand[-1])) % 1.0
                if self._distance(model, cand[None], target[a:a + w])[0] < gd[k].min():
                    start = cand
            prev = self._optimize(model, start, target[a:a + w])
            prev[-2] %= 1.0
            _, motion = self._candidate_acc(model, prev[None], w)
            vec = pose.encode(motion)[MARGIN:MARGIN + w]
            weight = 1.0 - np.abs(np.linspace(-1, 1, w + 2)[1:-1]) * 0.999
            acc_vec[a:a + w] += vec * weight[:, None]
            acc_w[a:a + w] += weight
        return pose.decode(acc_vec / acc_w[:, None], self.skeleton_, self.fps_)

    # ---- persistence ------------------------------------------------------------------------
    def get_state(self) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        arrays: dict[str, np.ndarray] = {}
        contents = sorted(self.models_)
        for i, c in enumerate(contents):
            arrays.update(self.models_[c].arrays(f"m{i}_"))
        return arrays, {"contents": contents}

    def set_state(self, arrays: dict[str, np.ndarray], values: dict[str, Any]) -> None:
        self.models_ = {c: MotionModel.from_arrays(arrays, f"m{i}_")
                        for i, c in enumerate(values["contents"])}
