"""Reading and writing motion and sensor files. Every parser raises :class:`FormatError`."""

from imuloco.errors import FormatError

__all__ = ["FormatError"]
