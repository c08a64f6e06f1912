"""Foot contacts, crossing events, steps and gait phases detected from a motion.

``gait_phases(motion)`` returns a :class:`GaitPhases` with everything per frame;
``segment(motion, kind)`` cuts a clip into ``(label, start, stop)`` phase segments for the
methods (``"gait8"``: Mousas 2017 Table 1, ``"eom2014"``: Eom et al. 2014, ``"support"``).
"""

from imuloco.phases.contacts import foot_contacts, part_contacts
from imuloco.phases.events import cadence, crossing_events, forward_difference, right_ahead
from imuloco.phases.gait import (
    EOM2014,
    GAIT8,
    KINDS,
    SUPPORT,
    GaitPhases,
    gait_phases,
    segment,
)

__all__ = [
    "EOM2014", "GAIT8", "KINDS", "SUPPORT", "GaitPhases", "cadence", "crossing_events",
    "foot_contacts", "forward_difference", "gait_phases", "part_contacts", "right_ahead",
    "segment",
]
