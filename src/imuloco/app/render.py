"""The stick-figure videos and the HTML viewer of motions side by side: what ``imuloco render``,
``reconstruct --video/--html`` and the demo draw (kept apart from :mod:`imuloco.app.pipeline`,
whose imports `render` does not need)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from imuloco.core.motion import Motion
from imuloco.io.atomic import check_outputs
from imuloco.viz.html import write_viewer
from imuloco.viz.skeleton import render_videos

if TYPE_CHECKING:
    from imuloco.app.confidence import Confidence


def render_outputs(motions: Sequence[Motion], titles: Sequence[str], video: Sequence[Path] = (),
                   html: Path | None = None, overwrite: bool = False, progress: bool = False,
                   max_seconds: float | None = None,
                   confidence: Sequence[Confidence | None] | None = None,
                   start: float | None = None, end: float | None = None) -> list[Path]:
    """Write the stick-figure video(s) (``.mp4``/``.gif``: each frame drawn once and streamed
    to every encoder, so memory does not grow with the recording; a GIF is cut at
    :data:`imuloco.viz.skeleton.GIF_MAX_SECONDS`) of the window ``start`` to ``end`` seconds
    (at most ``max_seconds``) and the HTML viewer of ``motions`` side by side (whole).
    ``confidence`` (per motion, or None) is drawn in the videos' strip and the viewer
    (predicted error per frame, unreliable frames marked)."""
    check_outputs([*video, html], overwrite)
    conf = list(confidence) if confidence is not None else [None] * len(motions)
    error_m = [None if c is None else c.error_m for c in conf]
    unreliable = [None if c is None else c.unreliable for c in conf]
    out = []
    if video:
        out += render_videos(motions, video, titles, start=start, end=end,
                             max_seconds=max_seconds, error_m=error_m, unreliable=unreliable,
                             overwrite=overwrite, progress=progress)
    if html is not None:
        out.append(write_viewer(motions, html, titles, title=" vs ".join(titles),
                                overwrite=overwrite, error_m=error_m, unreliable=unreliable))
    return out
