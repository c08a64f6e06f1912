"""Load a folder of BVH clips as a labelled MotionDatabase.

Labels come from a ``.json`` beside each clip (``{"content": i, "style": j}``, indices into
``cfg/content_label.txt`` and ``cfg/style_label.txt`` as in the Bandai-Namco data), with the
``dataset-2_`` prefix of those label names dropped. Clips without a ``.json`` get their name only.
"""

from __future__ import annotations

import json
from pathlib import Path

from tqdm.auto import tqdm

from imuloco.core.motion import MotionDatabase
from imuloco.errors import FormatError
from imuloco.io.cache import read_motion_cached


def _label_names(folder: Path, kind: str) -> list[str] | None:
    f = folder / "cfg" / f"{kind}_label.txt"
    if not f.is_file():
        return None
    return [ln.strip().removeprefix("dataset-2_") for ln in f.read_text().splitlines() if ln.strip()]


def read_labels(bvh: Path, contents: list[str] | None, styles: list[str] | None) -> dict[str, str]:
    """Labels of one clip from the ``.json`` beside it."""
    labels = {"name": bvh.stem}
    meta = bvh.with_suffix(".json")
    if not meta.is_file():
        return labels
    try:
        raw = json.loads(meta.read_text())
    except json.JSONDecodeError as e:
        raise FormatError(meta, e.lineno, f"expected JSON labels: {e.msg}") from None
    for key, names in (("content", contents), ("style", styles)):
        if key in raw:
            idx = raw[key]
            if names is not None and not (isinstance(idx, int) and 0 <= idx < len(names)):
                raise FormatError(meta, None, f"{key!r} must be an index below {len(names)}, got {idx!r}")
            labels[key] = names[idx] if names is not None else str(idx)
    return labels


def spread(n: int, limit: int | None) -> list[int]:
    """At most ``limit`` indices of ``range(n)``, evenly spaced, so that a quick run on a
    folder sorted by name still sees every motion type and style."""
    if not limit or limit >= n:
        return list(range(n))
    return sorted({round(i * (n - 1) / max(limit - 1, 1)) for i in range(limit)})


def load_database(
    folder: str | Path,
    content: list[str] | None = None,
    style: list[str] | None = None,
    limit: int | None = None,
    progress: bool = True,
    up: str = "auto",
    skip_frames: int = 0,
) -> MotionDatabase:
    """Read every ``*.bvh`` in ``folder`` (sorted by name) with its labels.

    Parameters
    ----------
    content, style : keep only clips with these labels (e.g. ``["walk", "run"]``).
    limit : read at most this many clips (after filtering, evenly spaced over the sorted
        names: see :func:`spread`), for quick runs.
    up, skip_frames : as for :func:`imuloco.io.bvh.read_bvh` (the vertical axis, ``"auto"``
        by default; leading frames to drop, such as a prepended T-pose).

    Parsed clips are cached by file content (:mod:`imuloco.io.cache`): a second load of the
    same folder reads ``.npz`` entries instead of parsing text.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f"motion folder {folder} does not exist")
    contents, styles = _label_names(folder, "content"), _label_names(folder, "style")
    files = sorted(folder.glob("*.bvh"))
    if not files:
        raise FileNotFoundError(f"no .bvh files in {folder}")
    chosen = []
    for f in files:
        lab = read_labels(f, contents, styles)
        if content and lab.get("content") not in content:
            continue
        if style and lab.get("style") not in style:
            continue
        chosen.append((f, lab))
    chosen = [chosen[i] for i in spread(len(chosen), limit)]
    clips = [read_motion_cached(f, up=up, skip_frames=skip_frames) for f, _ in tqdm(chosen, desc="loading clips", disable=not progress,
                                          unit="clip")]
    return MotionDatabase(clips, [lab for _, lab in chosen])


def load_sample(progress: bool = False) -> MotionDatabase:
    """The small sample bundled with the package (16 clips, see ``data/sample/README.md``)."""
    from imuloco.data import SAMPLE_DIR

    return load_database(SAMPLE_DIR, progress=progress)
