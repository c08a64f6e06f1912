"""Foot contacts from joint heights and speeds: :mod:`imuloco.core.contacts`, where the rig
(:class:`imuloco.core.retarget.Rig`, which measures a flat foot's pitch) can reach them; the
names stay importable from here, with the rest of the gait phases."""

from imuloco.core.contacts import (
    FEET,
    FLOOR_ROUGHNESS,
    MIN_FLOOR_SPAN,
    MIN_FLOOR_STEPS,
    SPEED_TOL,
    clean_mask,
    flat_foot_pitch,
    floor_height,
    floor_under,
    foot_contacts,
    foot_pitches,
    part_contacts,
    runs,
)

__all__ = [
    "FEET", "FLOOR_ROUGHNESS", "MIN_FLOOR_SPAN", "MIN_FLOOR_STEPS", "SPEED_TOL", "clean_mask",
    "flat_foot_pitch", "floor_height", "floor_under", "foot_contacts", "foot_pitches",
    "part_contacts", "runs",
]
