"""The registered method ``mousas2017``: hierarchical multivariate HMM with reactive
interpolation (Mousas, Sensors 2017, 17, 2589)."""

from __future__ import annotations

import itertools
from typing import Any, ClassVar

import numpy as np
from tqdm.auto import tqdm

from imuloco.core.motion import Motion
from imuloco.errors import ParameterError
from imuloco.methods.base import Method
from imuloco.methods.mousas2017.features import (
    layout,
    motion_features,
    registration_features,
)
from imuloco.methods.mousas2017.forward import Topology
from imuloco.methods.mousas2017.model import FrameStates, fit_frame_states
from imuloco.methods.mousas2017.registration import (
    NUM_PHASES,
    Segment,
    register_phase,
    segment_clip,
)
from imuloco.methods.mousas2017.stream import ENGINES, MousasStream
from imuloco.methods.params import Constraint, Options
from imuloco.methods.postprocess import pin_feet
from imuloco.methods.training import TrainingSet

# sec. 5.2's transition probabilities (each group sums to 1): of the phase level, of frames
A_PHASE = ("a_self_phase", "a_next_phase", "a_exit_phase")
A_FRAME = ("a_self_frame", "a_next_frame", "a_skip_frame")


class Mousas2017(Method):
    """Hierarchical multivariate HMM with reactive interpolation (Mousas 2017).

    Training (sec. 4-5): clips are cut into the 8 gait phases of Table 1, the segments of each
    phase are registered to a reference segment by DTW (warps shared by motion and sensor
    features), every registered frame becomes a frame state with a Gaussian over [x, y]
    (template learning, eq. 8-9) and its regression from y to x (eq. 5-7). Run time (sec. 6):
    the scaled forward algorithm on both levels, reactive interpolation of the K most probable
    segments of the most probable phase (eq. 10-13), velocity-based blending and foot-skate
    clean-up. Cost per frame is linear in the number of frame states (about the number of
    database frames), vectorised. See the sub-modules for each choice the paper leaves open;
    in short:

    - the next-phase transition spreads over the phases that followed in training (running has
      no double support, so Table 1's IC and PSW never occur in it);
    - the frame-state covariance is tied per (phase, registered frame) and shrunk;
    - interpolation weights ``a_k`` are the forward probabilities of the K segments,
      renormalised to sum 1;
    - the paper's 20 ms HMM window is shorter than one 30 fps frame: one frame is one
      observation;
    - the blending weight is not in the paper: 0.3 was the best of 0.3, 0.5 and 1 (no
      blending) on the first 120 clips of the shared data (all running; random-clips split:
      MPJPE 2.94, 2.98, 3.27 cm); shrinkage and ridge are regularisers the paper does not
      need to name;
    - ``sigma_scale`` = 1 makes eq. 9's sigma the y-marginal of the joint Gaussian (eq. 2);
      0.5 was 6 % better on a third of the shared data (MPJPE 3.28 against 3.49 cm, 0.25:
      3.45, 2: 4.54) but the default stays with the paper's model;
    - a missing sample (NaN, or a gap in a Recording) skips the emission update: the
      transitions alone carry the forward variables through a sensor dropout (sec. 5.2);
    - the shared data hold no jumps or hops; the speed-based cut for them (sec. 4.2) only
      splits overlong segments here.

    Parameters
    ----------
    K : segments interpolated (sec. 5.3: K = 5).
    a_self_phase, a_next_phase, a_exit_phase : upper-level transitions (sec. 5.2: 1/3 each).
    a_self_frame, a_next_frame, a_skip_frame : lower-level transitions (sec. 5.2: 1/3 each).
    blend : weight of the interpolated pose per frame in the velocity-based blending
        (1: no blending).
    shrinkage : pseudo-samples of the pooled covariance in each frame-state covariance.
    ridge : fraction of the global sensor variances added to U^YY.
    max_segment_s : segments longer than this are cut at root-speed extrema (sec. 4.2).
    foot_cleanup : pin the feet in predicted contact (sec. 6, after Kim et al. 2009).
    sigma_scale : emission standard deviations relative to the frame-state covariance's
        (eq. 9's sigma; 1: the y-marginal of the joint Gaussian of eq. 2).
    beam : the online forward variable is kept on this many segments, those of largest
        probability (:mod:`.beam`); 0: the exact forward step over every frame state. Model
        files written before the beam load with 0. On the shared data no width was both
        faster than the exact step and as accurate, also compiled
        (docs/results/mousas2017/speed.md).
    engine : how the online step runs: ``numba`` compiled kernels (the ``fast`` extra),
        ``numpy`` calls, or ``auto`` (numba when installed); the same step either way, to
        float rounding (:mod:`.compiled`). Model files written before it load with ``auto``.
    """

    summary = "hierarchical multivariate HMM + reactive interpolation (Mousas 2017), online"
    param_constraints: ClassVar[dict[str, Constraint]] = {
        **dict.fromkeys(A_PHASE + A_FRAME, "[0, 1]"), "shrinkage": "[0, inf)",
        "ridge": "[0, inf)", "max_segment_s": "(0, inf)",
        # emission deviations 10^-6 to 10^6 times the y-marginal's: the likelihoods are then
        # one spike or flat in float64 (1e300 overflowed squaring it)
        "sigma_scale": "[1e-6, 1e6]", "blend": "(0, 1]", "K": "[1, inf)", "beam": "[0, inf)",
        "engine": Options(*ENGINES)}
    supports_online = True

    # frames inside a gap of a recording (no sample for more than 0.1 s) reach the model as
    # missing: the forward pass then only propagates its transitions there (sec. 5.2, device
    # dropout)
    gaps_missing = True
    legacy_params: ClassVar[dict[str, Any]] = {"beam": 0, "engine": "auto"}
    stream_params: ClassVar[tuple[str, ...]] = ("beam", "engine")

    def __init__(
        self,
        K: int = 5,                      # sec. 5.3
        a_self_phase: float = 1 / 3,     # sec. 5.2
        a_next_phase: float = 1 / 3,
        a_exit_phase: float = 1 / 3,
        a_self_frame: float = 1 / 3,     # sec. 5.2
        a_next_frame: float = 1 / 3,
        a_skip_frame: float = 1 / 3,
        blend: float = 0.3,              # sec. 6 (velocity-based blending; weight not given)
        shrinkage: float = 10.0,
        ridge: float = 1e-2,
        max_segment_s: float = 0.5,      # sec. 4.2 (speed-based segmentation)
        foot_cleanup: bool = True,       # sec. 6
        sigma_scale: float = 1.0,        # eq. 9 (sigma not given)
        beam: int = 0,                   # sec. 6's forward algorithm, pruned (0: exact)
        engine: str = "auto",            # compiled (numba) or numpy step, same results
    ) -> None:
        self.K = K
        self.a_self_phase = a_self_phase
        self.a_next_phase = a_next_phase
        self.a_exit_phase = a_exit_phase
        self.a_self_frame = a_self_frame
        self.a_next_frame = a_next_frame
        self.a_skip_frame = a_skip_frame
        self.blend = blend
        self.shrinkage = shrinkage
        self.ridge = ridge
        self.max_segment_s = max_segment_s
        self.foot_cleanup = foot_cleanup
        self.sigma_scale = sigma_scale
        self.beam = beam
        self.engine = engine

    def check_together(self) -> None:
        for group in (A_PHASE, A_FRAME):
            a = [getattr(self, k) for k in group]
            if not abs(sum(a) - 1) <= 1e-9:
                raise ParameterError(group[0], f"method {self.name!r}: {', '.join(group)} are "
                                               f"probabilities that must sum to 1, got {a}")

    # ---- learning ---------------------------------------------------------------------------
    def learn(self, data: TrainingSet, progress: bool = False) -> None:
        examples = data.examples
        max_len = max(2, round(self.max_segment_s * data.fps))
        segs: list[Segment] = []
        xs, ys, regs = [], [], []
        follows = np.zeros((NUM_PHASES, NUM_PHASES))
        for i, ex in enumerate(tqdm(examples, desc="segmenting", disable=not progress,
                                    unit="clip")):
            clip_segs, contacts = segment_clip(ex.motion, i, max_len)
            for a, b in itertools.pairwise(clip_segs):
                if a.stop == b.start and a.phase != b.phase:
                    follows[a.phase, b.phase] += 1
            segs += clip_segs
            xs.append(motion_features(ex.motion, contacts))
            ys.append(np.asarray(ex.signals, dtype=np.float64))
            regs.append(registration_features(ex.motion))
        if not segs:
            raise ValueError("mousas2017: no whole gait-phase segment in the training clips "
                             "(clips too short or without steps)")
        bad = [i for i, y in enumerate(ys) if not np.all(np.isfinite(y))]
        if bad:
            raise ValueError(f"mousas2017: training signals of clip {examples[bad[0]].labels}"
                             " contain NaN or inf")
        phases, rx, ry = [], [], []
        for h in tqdm(range(NUM_PHASES), desc="registering (DTW)", disable=not progress):
            ph = [s for s in segs if s.phase == h]
            if not ph:
                continue
            x, y, _ = register_phase(ph, regs, xs, ys)
            phases.append(h)
            rx.append(x)
            ry.append(y)
        self.states_ = fit_frame_states(rx, ry, phases, self.shrinkage, self.ridge,
                                        self.sigma_scale)
        self.block_phase_ = np.array(phases, dtype=np.int64)
        self.block_count_ = np.array([x.shape[0] for x in rx], dtype=np.int64)
        self.block_length_ = np.array([x.shape[1] for x in rx], dtype=np.int64)
        self.next_phase_ = follows
        self._build(data.skeleton.num_joints)

    def _build(self, num_joints: int) -> None:
        """Derived structures: both levels' topologies, the pose layout of ``num_joints``."""
        a_phase = tuple(getattr(self, k) for k in A_PHASE)
        a_frame = tuple(getattr(self, k) for k in A_FRAME)
        self.lower_ = Topology(self.block_phase_, self.block_count_, self.block_length_,
                               self.next_phase_, a_frame, a_phase, dtype=np.float32)
        self.upper_ = Topology(self.block_phase_, np.ones_like(self.block_count_),
                               self.block_length_, self.next_phase_, a_frame, a_phase)
        self.layout_ = layout(num_joints)

    @property
    def pins_feet(self) -> bool:
        return self.foot_cleanup

    # ---- reconstruction ---------------------------------------------------------------------
    def stream(self, pin: bool | None = None, beam: int | None = None,
               engine: str | None = None) -> MousasStream:
        """A fresh online session; ``pin`` overrides ``foot_cleanup``, ``beam`` and ``engine``
        the model's."""
        return MousasStream(self, self.foot_cleanup if pin is None else pin, beam, engine)

    def reconstruct_signals(self, signals: np.ndarray) -> Motion:
        """Run the online stream over every frame (rows of NaN: missing samples), then pin the
        feet with :func:`imuloco.methods.postprocess.pin_feet` on the predicted contacts."""
        signals = np.asarray(signals, dtype=np.float64)
        n = len(signals)
        st = MousasStream(self, pin=False)  # beam: the model's
        rot = np.empty((n, self.skeleton_.num_joints, 4))
        root = np.empty((n, 3))
        contacts = np.empty((n, 2))
        for t in range(n):
            rot[t], root[t] = st.step(signals[t])
            contacts[t] = st.contacts
        motion = Motion(self.skeleton_, rot, root, self.fps_, "mousas2017")
        return pin_feet(motion, contacts) if self.foot_cleanup else motion

    # ---- persistence ------------------------------------------------------------------------
    def get_state(self) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        arrays = {f"states_{k}": v for k, v in self.states_.arrays().items()}
        arrays.update(block_phase=self.block_phase_, block_count=self.block_count_,
                      block_length=self.block_length_, next_phase=self.next_phase_)
        return arrays, {}

    def set_state(self, arrays: dict[str, np.ndarray], values: dict[str, Any]) -> None:
        self.states_ = FrameStates(**{k[len("states_"):]: arrays[k] for k in arrays
                                      if k.startswith("states_")})
        self.block_phase_ = arrays["block_phase"]
        self.block_count_ = arrays["block_count"]
        self.block_length_ = arrays["block_length"]
        self.next_phase_ = arrays["next_phase"]
        self._build(self.skeleton_.num_joints)
