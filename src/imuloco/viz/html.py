"""A self-contained interactive HTML viewer (orbit, play/pause, scrub, speed) of motions.

The page is the template ``viewer.html`` beside this module with the motions' world joint
positions embedded as JSON (integer millimetres, Y up) and a few lines of inline JavaScript that
project them on a 2-D canvas: no script or style is fetched from the network, so the file works
offline and can be mailed around. Several motions play side by side on one clock.
"""

from __future__ import annotations

import html
import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from imuloco.core.motion import Motion
from imuloco.viz.skeleton import follow_azimuth, joint_sides

TEMPLATE = Path(__file__).with_name("viewer.html")
DATA_MARK = "/*__IMULOCO_DATA__*/null"
TITLE_MARK = "__IMULOCO_TITLE__"


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
    if DATA_MARK not in page or TITLE_MARK not in page:
        raise RuntimeError(f"{TEMPLATE}: the data or title placeholder is missing")
    data = json.dumps(viewer_data(motions, titles, title), separators=(",", ":"))
    data = data.replace("</", "<\\/")  # a label cannot close the <script> element
    return page.replace(DATA_MARK, data).replace(TITLE_MARK, html.escape(title))


def write_viewer(motions: Sequence[Motion], path: str | Path, titles: Sequence[str] | None = None,
                 title: str | None = None, overwrite: bool = False) -> Path:
    """Write the viewer of ``motions`` to ``path`` (``.html``). Refuses to replace an existing
    file unless ``overwrite``."""
    path = Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists; pass overwrite=True (or --force) to replace it")
    page = viewer_html(motions, titles, title or motions[0].name or "imuloco")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(page, encoding="utf-8")
    return path
