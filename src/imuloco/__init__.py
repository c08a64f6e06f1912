"""imuloco: full-body locomotion reconstruction from one body-worn inertial sensor.

The package follows the data through the pipeline::

    ops, core -> io, sensors, phases -> methods -> measures -> viz -> app -> lab -> cli

``ops`` holds the shared maths, ``core`` the data types, ``measures`` the product's measures
(metrics, gait, strides), ``app`` the application (pipeline, batch, live) and ``lab`` the harness
that benchmarks the methods. Nothing imports upwards (``lint-imports`` checks it). See ``docs/glossary.md`` for the conventions
(quaternion order, axes, units).
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from imuloco.core.motion import Motion, MotionDatabase
    from imuloco.core.skeleton import Skeleton

__version__ = "0.1.0"

__all__ = ["Motion", "MotionDatabase", "Skeleton", "__version__"]

# imported on first use (PEP 562), so that ``imuloco --help`` does not import numpy and scipy
_LAZY = {"Motion": "imuloco.core.motion", "MotionDatabase": "imuloco.core.motion",
         "Skeleton": "imuloco.core.skeleton"}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'imuloco' has no attribute {name!r}")
