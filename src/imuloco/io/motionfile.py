"""Read any supported motion file by its extension."""

from __future__ import annotations

from pathlib import Path

from imuloco.core.motion import Motion
from imuloco.errors import FormatError
from imuloco.io.asf_amc import find_asf, read_asf_amc
from imuloco.io.bvh import read_bvh


def read_motion(path: str | Path, up: str = "auto", skip_frames: int = 0) -> Motion:
    """Read a ``.bvh`` file (or a CMU ``.amc`` with its ``.asf`` beside it) as a Motion, Y up.

    ``up`` is the file's vertical axis (``"auto"``, ``"y"`` or ``"z"``); ``skip_frames`` leading
    frames are dropped (a prepended T-pose)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".bvh":
        return read_bvh(path, up=up, skip_frames=skip_frames)
    if suffix == ".amc":
        return read_asf_amc(find_asf(path), path, up=up, skip_frames=skip_frames)
    raise FormatError(path, None, f"unsupported motion file type {suffix!r}; expected .bvh or "
                      ".amc")
