"""imuloco: full-body locomotion reconstruction from one body-worn inertial sensor.

The package follows the data through the pipeline::

    io -> sensors -> phases -> methods -> evaluate -> viz

with ``core`` for the data types and ``ops`` for the shared maths. See
``docs/glossary.md`` for the conventions (quaternion order, axes, units).
"""

from imuloco.core.motion import Motion, MotionDatabase
from imuloco.core.skeleton import Skeleton

__version__ = "0.1.0"

__all__ = ["Motion", "MotionDatabase", "Skeleton", "__version__"]
