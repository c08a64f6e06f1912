"""The files of one reconstruction, written as one set: ``imuloco reconstruct`` and ``batch``.

:meth:`Outputs.check` refuses, before any work, to replace a file without ``--force`` (or an
input); :func:`write_outputs` then writes the BVH, the video and viewer when asked, and the
JSON report last, each atomically (:mod:`imuloco.io.atomic`): a report beside its BVH marks the
set complete (``batch`` resumes on it).
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from imuloco.app.pipeline import render_outputs
from imuloco.app.report import ReconstructionReport
from imuloco.core.motion import Motion
from imuloco.io.atomic import atomic_write, check_outputs
from imuloco.io.bvh import write_bvh


@dataclass(frozen=True)
class Outputs:
    """Where a reconstruction's files go.

    bvh : the motion (lengths in ``unit``, ``cm`` or ``m``).
    report : the JSON report (:meth:`ReconstructionReport.to_json`), or None.
    video : a stick-figure video (``.mp4``, ``.gif``) of the first ``video_seconds`` (None:
        all), or None.
    html : the interactive viewer, or None.
    """

    bvh: Path
    report: Path | None = None
    video: Path | None = None
    html: Path | None = None
    video_seconds: float | None = None
    unit: str = "cm"

    def check(self, force: bool = False, inputs: Iterable[str | Path] = ()) -> None:
        """Raise :class:`~imuloco.errors.OutputExistsError` when a file exists and ``force``
        is False, or when one is among ``inputs``: before any work."""
        check_outputs([self.bvh, self.video, self.html, self.report], force, inputs=inputs)


def write_json(path: str | Path, data: Any) -> Path:
    """``data`` as indented JSON, atomically (a report's format)."""
    with atomic_write(path, "w") as f:
        f.write(json.dumps(data, indent=2) + "\n")
    return Path(path)


def write_outputs(outputs: Outputs, report: ReconstructionReport, motion: Motion | None = None,
                  progress: bool = False) -> list[Path]:
    """Write a reconstruction's files (replacing them: :meth:`Outputs.check` comes first):
    the BVH of ``motion`` (None: it was written piece by piece already,
    :func:`imuloco.app.chunked.reconstruct_to_bvh`), the video and viewer (which need
    ``motion``), then the report. Returns the paths written, in that order."""
    written = [Path(outputs.bvh)]
    if motion is not None:
        write_bvh(motion, outputs.bvh, unit=outputs.unit, overwrite=True)
        if outputs.video or outputs.html:
            written += render_outputs([motion], [f"{motion.name} ({report.method})"],
                                      [outputs.video] if outputs.video else [], outputs.html,
                                      overwrite=True, progress=progress,
                                      max_seconds=outputs.video_seconds,
                                      confidence=[report.confidence])
    elif outputs.video or outputs.html:
        raise ValueError("a video or viewer needs the motion")
    if outputs.report is not None:
        written.append(write_json(outputs.report, report.to_json()))
    return written
