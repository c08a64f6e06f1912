"""A self-contained interactive HTML viewer (orbit, play/pause, scrub, speed) of motions.

The page is the template ``viewer.html`` beside this module with the motions' world joint
positions embedded as JSON (integer millimetres, Y up) and the stick-figure drawing of
``stickfigure.js`` (shared with the live page, :mod:`imuloco.app.live.server`) inlined: no script or
style is fetched from the network, so the file works offline and can be mailed around. Several
motions play side by side on one clock.
"""

from __future__ import annotations

import html
import json
import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from imuloco.core.motion import Motion
from imuloco.io.atomic import atomic_write, check_output
from imuloco.viz.skeleton import follow_azimuth, joint_sides

TEMPLATE = Path(__file__).with_name("viewer.html")
STICKFIGURE = Path(__file__).with_name("stickfigure.js")
DATA_MARK = "/*__IMULOCO_DATA__*/null"
TITLE_MARK = "__IMULOCO_TITLE__"
STICKFIGURE_MARK = "/*__IMULOCO_STICKFIGURE__*/"


def _fill(page: str, values: dict[str, str]) -> str:
    """``page`` with every placeholder (a key of ``values``) replaced in one pass, so that a
    value holding another placeholder's text (a motion's label) is left as it is."""
    return re.sub("|".join(map(re.escape, values)), lambda m: values[m.group(0)], page)


def stickfigure_js() -> str:
    """The text of ``stickfigure.js`` (defines ``StickFigure``), to inline in a ``<script>``."""
    js = STICKFIGURE.read_text(encoding="utf-8")
    if "</script" in js.lower():
        raise RuntimeError(f"{STICKFIGURE}: the script cannot hold '</script'")
    return js


def inline_stickfigure(page: str) -> str:
    """``page`` (HTML) with the placeholder ``/*__IMULOCO_STICKFIGURE__*/`` (inside a
    ``<script>`` element) replaced by :func:`stickfigure_js`; a page without the placeholder
    comes back unchanged."""
    return _fill(page, {STICKFIGURE_MARK: stickfigure_js()})


def viewer_data(motions: Sequence[Motion], titles: Sequence[str] | None = None,
                title: str = "imuloco") -> dict:
    """The JSON the viewer reads.

    All motions are drawn at the frame times of the first (nearest frame, clamped), on the
    first motion's skeleton topology (they must share ``parents``).

    Returns
    -------
    dict with ``title``, ``fps``, ``frames``, ``parents``, ``sides``, ``head`` (joint index),
    ``floor`` and ``height`` (metres), ``azimuth`` (radians, the first frame's camera),
    ``turn`` (per frame, radians: how far the first figure's heading turned since the first
    frame, which the camera follows in "follow" mode) and ``tracks``: a list of
    ``{"label", "positions"}`` with positions flattened from (T, J, 3) integer millimetres.
    """
    if not motions:
        raise ValueError("viewer: no motion to show")
    first = motions[0]
    sk = first.skeleton
    for m in motions[1:]:
        if not np.array_equal(m.skeleton.parents, sk.parents):
            raise ValueError(f"viewer: motion {m.name!r} has another skeleton topology than "
                             f"{first.name!r}")
    titles = list(titles) if titles is not None else [m.name for m in motions]
    times = first.times
    tracks, floors = [], []
    for m, label in zip(motions, titles):
        idx = np.clip(np.round(times * m.fps).astype(int), 0, m.num_frames - 1)
        pos = m.positions()[idx]
        floors.append(float(np.percentile(pos[:, :, 1].min(axis=1), 5)))
        tracks.append({"label": label,
                       "positions": np.round(pos * 1000).astype(np.int64).ravel().tolist()})
    pos0 = first.positions()[0]
    az = follow_azimuth(first)
    try:
        head = sk.part("head")
    except KeyError:
        head = int(np.argmax(pos0[:, 1]))
    return {
        "title": title, "fps": float(first.fps), "frames": int(first.num_frames),
        "parents": sk.parents.tolist(), "sides": joint_sides(sk), "head": head,
        "floor": min(floors), "height": max(1.0, float(np.ptp(pos0[:, 1]))),
        "azimuth": float(az[0]), "turn": np.round(az - az[0], 3).tolist(), "tracks": tracks,
    }


def viewer_html(motions: Sequence[Motion], titles: Sequence[str] | None = None,
                title: str = "imuloco") -> str:
    """The viewer page (a str of HTML) for ``motions``, see :func:`viewer_data`."""
    page = TEMPLATE.read_text(encoding="utf-8")
    if any(mark not in page for mark in (DATA_MARK, TITLE_MARK, STICKFIGURE_MARK)):
        raise RuntimeError(f"{TEMPLATE}: the data, title or stick-figure placeholder is missing")
    data = json.dumps(viewer_data(motions, titles, title), separators=(",", ":"))
    data = data.replace("</", "<\\/")  # a label cannot close the <script> element
    return _fill(page, {DATA_MARK: data, TITLE_MARK: html.escape(title),
                        STICKFIGURE_MARK: stickfigure_js()})


def write_viewer(motions: Sequence[Motion], path: str | Path, titles: Sequence[str] | None = None,
                 title: str | None = None, overwrite: bool = False) -> Path:
    """Write the viewer of ``motions`` to ``path`` (``.html``). Refuses to replace an existing
    file unless ``overwrite``."""
    path = Path(path)
    check_output(path, overwrite)
    page = viewer_html(motions, titles, title or motions[0].name or "imuloco")
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(path, "w") as f:
        f.write(page)
    return path
