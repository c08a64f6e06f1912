"""Read any supported motion file by its extension."""

from __future__ import annotations

from pathlib import Path

from imuloco.core.motion import Motion
from imuloco.errors import FormatError
from imuloco.io.bvh import read_bvh


def read_motion(path: str | Path) -> Motion:
    """Read a ``.bvh`` file (or a CMU ``.amc`` with its ``.asf`` beside it) as a Motion."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".bvh":
        return read_bvh(path)
    if suffix == ".amc":
        from imuloco.io.asf_amc import find_asf, read_asf_amc

        return read_asf_amc(find_asf(path), path)
    raise FormatError(path, None, f"unsupported motion file type {suffix!r}; expected .bvh or "
                      ".amc")
