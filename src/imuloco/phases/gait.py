"""Gait phases from foot contacts and crossing events.

Three labellings of every frame:

``gait8``
    The eight phases of one reference leg's cycle, Mousas 2017 sec. 4.2, Table 1 (for the right
    leg; RH/RT/LH/LT heel/toe contacts, RCE/LCE which ankle leads). Each phase runs from its
    start condition to the next phase's:

    ====  =============================  ==========================================
    IC    RH & LT                        double support, right ankle leading
    LR    RH & RT & !LT                  right single support, right leading
    MST   RH & RT & LCE                  right single support, left leading
    TST   RT & !LH & !LT                 right heel off, left still in swing
    PSW   RT & LH                        double support, left leading
    ISW   !RT & LH & LT                  right swing, right trailing
    MSW   RCE & LH & LT                  right swing, right leading, left heel down
    TSW   !RH & !RT & LT                 right swing, right leading, left heel off
    ====  =============================  ==========================================

    The column on the right is how the start conditions are read as frame states here; a foot
    "down" is heel or toe. Running has no double support, so IC and PSW are skipped, and its
    flight frames fall in ISW (after toe-off) or TSW (before the strike).
``eom2014``
    The coarser phases of Eom et al. 2014 sec. 5.4 and Fig. 4, split at toe-offs: ``start``
    (standing until the first foot leaves), ``first_step`` (from that toe-off to the other
    foot's), then ``right_step``/``left_step`` (from that foot's toe-off until the other foot's)
    and ``stop`` (from the last toe-off to the end, when the clip ends standing). Clips that
    begin or end mid-gait have no ``start``/``first_step``/``stop``.
``support``
    ``double``, ``left``, ``right`` (single support on that foot) and ``flight`` (no foot down).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from imuloco.core.motion import Motion
from imuloco.errors import InputError
from imuloco.phases.contacts import SPEED_TOL, foot_contacts
from imuloco.phases.events import (
    cadence,
    crossing_events,
    forward_difference,
    heading_angle,
    offsets,
    onsets,
    right_ahead,
)

GAIT8 = ("IC", "LR", "MST", "TST", "PSW", "ISW", "MSW", "TSW")
EOM2014 = ("start", "first_step", "right_step", "left_step", "stop")
SUPPORT = ("double", "left", "right", "flight")
KINDS = ("gait8", "eom2014", "support")


def _int_runs(labels: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    edges = np.flatnonzero(labels[1:] != labels[:-1]) + 1
    starts = np.concatenate([[0], edges]).astype(np.int64)
    stops = np.concatenate([edges, [labels.size]]).astype(np.int64)
    return starts, stops, labels[starts]


def gait8_states(
    ref_heel: np.ndarray,
    ref_foot: np.ndarray,
    other_heel: np.ndarray,
    other_foot: np.ndarray,
    ref_ahead: np.ndarray,
) -> np.ndarray:
    """Frame-wise Table 1 phase (index into :data:`GAIT8`) from contact and crossing states.

    All arguments : ndarray, shape (...), bool: the reference leg's heel and foot (heel or toe)
    contacts, the other leg's, and whether the reference ankle leads.
    """
    stance, other = np.asarray(ref_foot, bool), np.asarray(other_foot, bool)
    ahead, heel, oheel = (np.asarray(a, bool) for a in (ref_ahead, ref_heel, other_heel))
    conditions = [
        stance & other & ahead,              # IC
        stance & ~other & ahead,             # LR
        stance & ~other & ~ahead & heel,     # MST
        stance & ~other & ~ahead & ~heel,    # TST
        stance & other & ~ahead,             # PSW
        ~stance & ~ahead,                    # ISW
        ~stance & ahead & oheel,             # MSW
        ~stance & ahead & ~oheel,            # TSW
    ]
    return np.select(conditions, np.arange(8)).astype(np.int64)


def enforce_cycle(labels: np.ndarray, n: int, min_back: int) -> np.ndarray:
    """Make cyclic phase labels move forward: a run that steps back by fewer than ``n / 2``
    phases and lasts fewer than ``min_back`` frames keeps the phase before it.

    labels : ndarray, shape (T,), int in ``[0, n)``.

    The walk over runs is sequential by nature (each decision depends on the state kept so
    far); there are a few runs per step, not one per frame.
    """
    labels = np.asarray(labels, dtype=np.int64)
    if labels.size == 0:
        return labels.copy()
    starts, stops, vals = _int_runs(labels)
    kept = vals.copy()
    cur = vals[0]
    for k in range(1, vals.size):
        back = (vals[k] - cur) % n > n // 2
        if not back or stops[k] - starts[k] >= min_back:
            cur = vals[k]
        kept[k] = cur
    return np.repeat(kept, stops - starts)


def eom2014_labels(
    left_foot: np.ndarray, right_foot: np.ndarray, standing_start: bool, standing_end: bool
) -> np.ndarray:
    """Eom et al. 2014 phase per frame (index into :data:`EOM2014`).

    left_foot, right_foot : ndarray, shape (T,), bool foot contacts.
    standing_start, standing_end : whether the clip begins / ends standing.
    """
    left_foot, right_foot = np.asarray(left_foot, bool), np.asarray(right_foot, bool)
    t = left_foot.size
    off_l, off_r = offsets(left_foot), offsets(right_foot)
    events = np.concatenate([off_r, off_l])
    step = np.concatenate([np.full(off_r.size, 2), np.full(off_l.size, 3)])  # right_/left_step
    order = np.argsort(events, kind="stable")
    events, step = events[order], step[order]
    if events.size == 0:
        if standing_start:
            return np.zeros(t, dtype=np.int64)
        return np.full(t, 2 if not right_foot[0] else 3, dtype=np.int64)
    k = np.searchsorted(events, np.arange(t), side="right") - 1
    before = 0 if standing_start else 5 - step[0]  # the other foot is the one moving
    labels = np.where(k >= 0, step[np.maximum(k, 0)], before)
    if standing_start:
        labels[k == 0] = 1
    if standing_end:
        labels[k == events.size - 1] = 4
    return labels.astype(np.int64)


def support_labels(left_foot: np.ndarray, right_foot: np.ndarray) -> np.ndarray:
    """Support per frame (index into :data:`SUPPORT`). left_foot, right_foot : (...) bool."""
    left_foot, right_foot = np.asarray(left_foot, bool), np.asarray(right_foot, bool)
    return np.select([left_foot & right_foot, left_foot, right_foot], [0, 1, 2], 3).astype(
        np.int64)


@dataclass
class GaitPhases:
    """Contacts, events and phase labels of one clip (see :func:`gait_phases`).

    Attributes
    ----------
    fps : frames per second.
    contacts : ``{left,right}_{heel,toe,foot}`` -> ndarray, shape (T,), bool.
    right_ahead : ndarray, shape (T,), bool: the right ankle leads along the heading.
    crossings : ``right`` (RCE) / ``left`` (LCE) -> frame indices.
    phase : ndarray, shape (T,), int: Table 1 phase of the reference leg, into ``phase_names``.
    phase_names : :data:`GAIT8`.
    reference : ``"right"`` or ``"left"``, the leg ``phase`` describes.
    eom2014 : ndarray, shape (T,), int into :data:`EOM2014`.
    support : ndarray, shape (T,), int into :data:`SUPPORT`.
    steps : ``left`` / ``right`` -> frames of foot strikes: onsets of foot contact (heel or toe,
        whichever lands first; the heel strike in walking), so forefoot landings count too.
    cadence_spm : steps per minute (NaN with fewer than two strikes).
    """

    fps: float
    contacts: dict[str, np.ndarray]
    right_ahead: np.ndarray
    crossings: dict[str, np.ndarray]
    phase: np.ndarray
    eom2014: np.ndarray
    support: np.ndarray
    steps: dict[str, np.ndarray]
    cadence_spm: float
    reference: str = "right"
    phase_names: tuple[str, ...] = field(default=GAIT8)

    @property
    def num_frames(self) -> int:
        return int(self.phase.size)

    @property
    def flight(self) -> np.ndarray:
        """Frames with neither foot down, shape (T,), bool."""
        return self.support == SUPPORT.index("flight")

    def labels(self, kind: str = "gait8") -> tuple[np.ndarray, tuple[str, ...]]:
        """Per-frame labels (T,) int and their names for ``kind`` in :data:`KINDS`."""
        if kind == "gait8":
            return self.phase, self.phase_names
        if kind == "eom2014":
            return self.eom2014, EOM2014
        if kind == "support":
            return self.support, SUPPORT
        raise ValueError(f"unknown phase kind {kind!r}; expected one of {KINDS}")

    def names(self, kind: str = "gait8") -> list[str]:
        """Per-frame label names, length T."""
        labels, names = self.labels(kind)
        return [names[i] for i in labels]

    def to_dict(self) -> dict:
        """A JSON-ready report: ``fps``, ``frames``, ``reference``, ``contacts`` (0/1 per frame
        for ``{left,right}_{heel,toe}``), ``phase`` (gait8 names per frame), ``eom2014`` and
        ``support`` (names per frame), ``steps`` (strike frames per foot), ``cadence_spm``
        (``None`` when undefined) and ``flight_frames`` (frame indices)."""
        cad = self.cadence_spm
        return {
            "fps": self.fps, "frames": self.num_frames, "reference": self.reference,
            "contacts": {k: self.contacts[k].astype(int).tolist()
                         for k in ("left_heel", "left_toe", "right_heel", "right_toe")},
            "phase": self.names("gait8"), "eom2014": self.names("eom2014"),
            "support": self.names("support"),
            "steps": {k: v.tolist() for k, v in self.steps.items()},
            "cadence_spm": None if np.isnan(cad) else round(cad, 2),
            "flight_frames": np.flatnonzero(self.flight).tolist(),
        }

    def segments(self, kind: str = "gait8") -> list[tuple[str, int, int]]:
        """Maximal runs of one label as ``(label, start, stop)``, ``stop`` exclusive, in order;
        they tile ``range(T)``. Segments touching the clip's ends may be partial phases."""
        labels, names = self.labels(kind)
        if labels.size == 0:
            return []
        starts, stops, vals = _int_runs(labels)
        return [(names[v], int(a), int(b)) for v, a, b in zip(vals, starts, stops)]


def gait_phases(
    motion: Motion,
    reference: str = "right",
    cross_tol: float = 0.02,
    heading_sigma_s: float = 0.1,
    min_back_s: float = 0.1,
    **tolerances: float,
) -> GaitPhases:
    """Detect contacts, crossing events, steps and phases of a walking or running clip.

    Parameters
    ----------
    motion : Motion whose skeleton maps pelvis, hips, ankles and toes.
    reference : leg whose cycle ``phase`` follows (Mousas 2017 segments the right leg).
    cross_tol : hysteresis of the crossing state, in leg lengths.
    heading_sigma_s : smoothing of the heading angle, seconds.
    min_back_s : a phase that steps backwards in the cycle must last this long to count.
    **tolerances : contact tolerances, see :func:`imuloco.phases.contacts.part_contacts`.
    """
    if reference not in ("left", "right"):
        raise ValueError(f"reference must be 'left' or 'right', got {reference!r}")
    if motion.num_frames < 2:
        raise InputError(f"motion {motion.name!r} has {motion.num_frames} frame: gait phases "
                         "need at least 2")
    leg = motion.skeleton.leg_length()
    fps = motion.fps
    contacts = foot_contacts(motion, **tolerances)
    pos = motion.part_positions(["pelvis", "left_hip", "right_hip", "left_ankle", "right_ankle"])
    theta = heading_angle(pos[:, 1], pos[:, 2], heading_sigma_s * fps)
    ahead = right_ahead(forward_difference(pos[:, 4], pos[:, 3], pos[:, 0], theta),
                        cross_tol * leg)
    ref, other = (reference, "left" if reference == "right" else "right")
    ref_ahead = ahead if reference == "right" else ~ahead
    raw = gait8_states(contacts[f"{ref}_heel"], contacts[f"{ref}_foot"],
                       contacts[f"{other}_heel"], contacts[f"{other}_foot"], ref_ahead)
    phase = enforce_cycle(raw, len(GAIT8), max(1, round(min_back_s * fps)))

    left, right = contacts["left_foot"], contacts["right_foot"]
    speed_tol = tolerances.get("speed_tol", SPEED_TOL) * leg  # standing: feet down, pelvis still
    hvel = np.gradient(pos[:, 0, [0, 2]], axis=0) * fps
    standing = left & right & (np.linalg.norm(hvel, axis=-1) < speed_tol)
    steps = {"left": onsets(left), "right": onsets(right)}
    return GaitPhases(
        fps=fps, contacts=contacts, right_ahead=ahead, crossings=crossing_events(ahead),
        phase=phase, eom2014=eom2014_labels(left, right, bool(standing[0]), bool(standing[-1])),
        support=support_labels(left, right), steps=steps,
        cadence_spm=cadence([steps["left"], steps["right"]], fps), reference=reference,
    )


def segment(motion: Motion, kind: str = "gait8", **options: float | str) -> list[
        tuple[str, int, int]]:
    """Split a clip into phase segments ``(label, start, stop)`` (stop exclusive).

    kind : ``"gait8"`` (Mousas 2017 Table 1), ``"eom2014"`` (Eom et al. 2014) or ``"support"``.
    **options : passed to :func:`gait_phases`.
    """
    if kind not in KINDS:
        raise ValueError(f"unknown phase kind {kind!r}; expected one of {KINDS}")
    return gait_phases(motion, **options).segments(kind)  # type: ignore[arg-type]
