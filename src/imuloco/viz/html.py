"""A self-contained interactive HTML viewer (orbit, play/pause, scrub, speed) of motions.

The page is the template ``viewer.html`` beside this module with the motions' world joint
positions embedded as JSON (integer millimetres, Y up) and the stick-figure drawing of
``stickfigure.js`` (shared with the live page, :mod:`imuloco.app.live.server`) inlined: no script or
style is fetched from the network, so the file works offline and can be mailed around. Several
motions play side by side on one clock. A motion with a per-frame predicted error (a method's
confidence, :class:`imuloco.methods.base.Reconstruction`) shows it in its panel and on a
timeline strip under the controls, and frames the method flags as unreliable are marked: the
figure drawn over an amber halo, with the label :data:`UNRELIABLE_LABEL`.
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
UNRELIABLE_LABEL = "unreliable: the model does not know this motion"  # also in viewer.html


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
                title: str = "imuloco",
                error_m: Sequence[np.ndarray | None] | None = None,
                unreliable: Sequence[np.ndarray | None] | None = None) -> dict:
    """The JSON the viewer reads.

    All motions are drawn at the frame times of the first (nearest frame, clamped), on the
    first motion's skeleton topology (they must share ``parents``). ``error_m`` and
    ``unreliable``: per motion, its per-frame predicted error (T,) in metres and unreliable
    flags (T,) bool, or None (a motion without them).

    Returns
    -------
    dict with ``title``, ``fps``, ``frames``, ``parents``, ``sides``, ``head`` (joint index),
    ``floor`` and ``height`` (metres), ``azimuth`` (radians, the first frame's camera),
    ``turn`` (per frame, radians: how far the first figure's heading turned since the first
    frame, which the camera follows in "follow" mode) and ``tracks``: a list of
    ``{"label", "positions"}`` with positions flattened from (T, J, 3) integer millimetres,
    and where given ``error_mm`` (per frame, 0.1 mm, None for NaN) and ``unreliable`` (per
    frame, 0 or 1).
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
    errors = list(error_m) if error_m is not None else [None] * len(motions)
    flags = list(unreliable) if unreliable is not None else [None] * len(motions)
    times = first.times
    tracks, floors = [], []
    for m, label, err, flag in zip(motions, titles, errors, flags):
        idx = np.clip(np.round(times * m.fps).astype(int), 0, m.num_frames - 1)
        pos = m.positions()[idx]
        floors.append(float(np.percentile(pos[:, :, 1].min(axis=1), 5)))
        track = {"label": label,
                 "positions": np.round(pos * 1000).astype(np.int64).ravel().tolist()}
        if err is not None:
            e = np.asarray(err, dtype=np.float64)[np.minimum(idx, len(err) - 1)]
            track["error_mm"] = [None if not np.isfinite(v) else round(float(v) * 1000, 1)
                                 for v in e]
        if flag is not None:
            track["unreliable"] = np.asarray(flag, dtype=bool)[
                np.minimum(idx, len(flag) - 1)].astype(int).tolist()
        tracks.append(track)
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
                title: str = "imuloco", error_m: Sequence[np.ndarray | None] | None = None,
                unreliable: Sequence[np.ndarray | None] | None = None) -> str:
    """The viewer page (a str of HTML) for ``motions``, see :func:`viewer_data`."""
    page = TEMPLATE.read_text(encoding="utf-8")
    if any(mark not in page for mark in (DATA_MARK, TITLE_MARK, STICKFIGURE_MARK)):
        raise RuntimeError(f"{TEMPLATE}: the data, title or stick-figure placeholder is missing")
    data = json.dumps(viewer_data(motions, titles, title, error_m, unreliable),
                      separators=(",", ":"))
    data = data.replace("</", "<\\/")  # a label cannot close the <script> element
    return _fill(page, {DATA_MARK: data, TITLE_MARK: html.escape(title),
                        STICKFIGURE_MARK: stickfigure_js()})


def write_viewer(motions: Sequence[Motion], path: str | Path, titles: Sequence[str] | None = None,
                 title: str | None = None, overwrite: bool = False,
                 error_m: Sequence[np.ndarray | None] | None = None,
                 unreliable: Sequence[np.ndarray | None] | None = None) -> Path:
    """Write the viewer of ``motions`` to ``path`` (``.html``; ``error_m``, ``unreliable``: see
    :func:`viewer_data`). Refuses to replace an existing file unless ``overwrite``."""
    path = Path(path)
    check_output(path, overwrite)
    page = viewer_html(motions, titles, title or motions[0].name or "imuloco", error_m,
                       unreliable)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(path, "w") as f:
        f.write(page)
    return path
