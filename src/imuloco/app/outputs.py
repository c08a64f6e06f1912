"""The files of one reconstruction, written as one set: ``imuloco reconstruct`` and ``batch``.

:meth:`Outputs.check` refuses, before any work, to replace a file without ``--force`` (or an
input); :func:`write_outputs` then stages the BVH, the video and viewer when asked, and the
JSON report, and renames them together, the report last (:class:`imuloco.io.atomic.OutputSet`).
The report names its BVH by SHA-256 (``outputs``; in ``batch`` also ``batch.bvh_sha256``), so a
run killed between two renames leaves a report that does not match: ``batch`` redoes it.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from imuloco.app.export import write_reconstruction
from imuloco.app.render import render_outputs
from imuloco.app.report import ReconstructionReport
from imuloco.core.motion import Motion
from imuloco.core.rigs import DEFAULT_RIG
from imuloco.io.atomic import OutputSet, atomic_write, check_outputs, sha256_file


@dataclass(frozen=True)
class Outputs:
    """Where a reconstruction's files go.

    bvh : the motion (lengths in ``unit``, ``cm`` or ``m``).
    report : the JSON report (:meth:`ReconstructionReport.to_json`), or None.
    video : a stick-figure video (``.mp4``, ``.gif``) of the first ``video_seconds`` (None:
        all), or None.
    html : the interactive viewer, or None.
    rig : the rig preset the motion is written on (:mod:`imuloco.core.rigs`; None: the
        motion's own skeleton, e.g. a user's rig it was retargeted onto).
    """

    bvh: Path
    report: Path | None = None
    video: Path | None = None
    html: Path | None = None
    video_seconds: float | None = None
    unit: str = "cm"
    rig: str | None = DEFAULT_RIG

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
    bvh = Path(outputs.bvh)
    written = [bvh]
    if motion is None and (outputs.video or outputs.html):
        raise ValueError("a video or viewer needs the motion")
    with OutputSet() as outs:  # all staged, then renamed together, the report last
        if motion is not None:
            write_reconstruction(motion, outs.path(bvh), outputs.rig, unit=outputs.unit,
                                 overwrite=True)
            digest = outs.sha256(bvh)
            if outputs.video or outputs.html:
                render_outputs([motion], [f"{motion.name} ({report.method})"],
                               [outs.path(outputs.video)] if outputs.video else [],
                               outs.path(outputs.html) if outputs.html else None,
                               overwrite=True, progress=progress,
                               max_seconds=outputs.video_seconds,
                               confidence=[report.confidence])
                written += [p for p in (outputs.video, outputs.html) if p]
        else:  # written piece by piece before: its report names what is there
            digest = sha256_file(bvh)
        if getattr(report, "batch", None) is not None:
            report.batch["bvh_sha256"] = digest  # batch's resume checks it there
        if outputs.report is not None:
            with outs.open(outputs.report, "w") as f:
                f.write(json.dumps({**report.to_json(),
                                    "outputs": {"bvh": bvh.name, "bvh_sha256": digest}},
                                   indent=2) + "\n")
            written.append(Path(outputs.report))
    return written
