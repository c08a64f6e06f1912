"""Load folders of BVH clips as one labelled MotionDatabase.

Labels: ``name`` (the file stem) and ``dataset`` (the folder's name), then either a ``.json``
beside each clip (``{"content": i, "style": j}``, indices into ``cfg/content_label.txt`` and
``cfg/style_label.txt`` as in the Bandai-Namco data, with the ``dataset-N_`` prefix of those
label names dropped) or, without one, the clip's row in a ``trials.csv`` in the folder (columns
``file``, ``description`` and optionally ``subject``, as in the shared ``cmu-iclone``): the
description is kept and mapped to a content (:data:`CONTENT_RULES`, e.g. ``"run/jog"`` ->
``run``), ``slow``/``brisk`` to a style.

A leading pose that the motion jumps out of (the T-pose converters prepend, as in
``cmu-iclone``) is dropped: see :func:`drop_leading_pose`.

Several folders (:func:`load_databases`) become one training set on the first folder's
skeleton and frame rate: clips of other skeletons are retargeted by body part
(:mod:`imuloco.core.retarget`) and resampled.
"""

from __future__ import annotations

import csv
import json
import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from imuloco.core.motion import Motion, MotionDatabase
from imuloco.core.retarget import Rig, resampled, retarget, same_family
from imuloco.data import SAMPLE_DIR
from imuloco.errors import FormatError, MissingInputError
from imuloco.io.cache import read_motion_cached

TRIALS_FILE = "trials.csv"
# A trial description (lower case) -> content: the first pattern found wins.
CONTENT_RULES: tuple[tuple[str, str], ...] = (
    (r"dribble.*left turn", "dribble-turn-left"), (r"dribble.*right turn", "dribble-turn-right"),
    (r"backward dribble", "dribble-back"), (r"sideways dribble", "dribble-side"),
    (r"dribble", "dribble"), (r"uneven terrain", "walk-uneven"), (r"\bjump", "jump"),
    (r"\b(run|jog)", "run"), (r"\bwalk.*\bback|backwards? walk", "walk-back"),
    (r"\bwalk", "walk"),
)
JUMP_M = 0.1  # a leading pose is dropped when the first frame step exceeds this (metres) ...
JUMP_RATIO = 10.0  # ... and this many times the clip's median frame step


def _label_names(folder: Path, kind: str) -> list[str] | None:
    f = folder / "cfg" / f"{kind}_label.txt"
    if not f.is_file():
        return None
    return [re.sub(r"^dataset-\d+_", "", ln.strip()) for ln in f.read_text().splitlines()
            if ln.strip()]


def content_of(description: str) -> str | None:
    """The content a trial description names (:data:`CONTENT_RULES`), or None."""
    text = description.lower()
    return next((c for pat, c in CONTENT_RULES if re.search(pat, text)), None)


def read_trials(folder: Path) -> dict[str, dict[str, str]]:
    """Labels by file stem from ``folder/trials.csv`` ({} when there is none)."""
    f = folder / TRIALS_FILE
    if not f.is_file():
        return {}
    with f.open(newline="", encoding="utf-8-sig") as fh:
        rows = list(csv.DictReader(fh))
    cols = set(rows[0]) if rows else set()
    if not {"file", "description"} <= cols:
        raise FormatError(f, 1, f"expected the columns 'file' and 'description' (and "
                          f"optionally 'subject'), found {sorted(cols)}")
    out = {}
    for line, row in enumerate(rows, start=2):
        if not row["file"]:
            raise FormatError(f, line, "expected a file name in column 'file'")
        desc = (row["description"] or "").strip()
        lab = {"description": desc}
        if (content := content_of(desc)) is not None:
            lab["content"] = content
        if m := re.match(r"(slow|brisk)\b", desc.lower()):
            lab["style"] = m.group(1)
        if row.get("subject"):
            lab["subject"] = row["subject"].strip()
        out[Path(row["file"].strip()).stem] = lab
    return out


def read_labels(bvh: Path, contents: list[str] | None, styles: list[str] | None,
                trials: dict[str, dict[str, str]] | None = None) -> dict[str, str]:
    """Labels of one clip from the ``.json`` beside it, else from its ``trials`` row."""
    labels = {"name": bvh.stem, "dataset": bvh.parent.name}
    meta = bvh.with_suffix(".json")
    if not meta.is_file():
        return {**labels, **(trials or {}).get(bvh.stem, {})}
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


def drop_leading_pose(motion: Motion) -> Motion:
    """``motion`` without its first frame when the motion jumps out of it: a joint moves more
    than :data:`JUMP_M` relative to the pelvis from frame 0 to 1, and more than
    :data:`JUMP_RATIO` times the clip's median frame step (a converter's prepended T-pose;
    mocap never moves so between frames)."""
    if motion.num_frames < 3:
        return motion
    pos = motion.positions()
    pos = pos - pos[:, :1]
    step = np.linalg.norm(np.diff(pos, axis=0), axis=-1).max(axis=1)  # (T-1,)
    if step[0] > max(JUMP_M, JUMP_RATIO * float(np.median(step[1:]))):
        return motion.slice(1, motion.num_frames)
    return motion


def load_database(
    folder: str | Path,
    content: list[str] | None = None,
    style: list[str] | None = None,
    limit: int | None = None,
    progress: bool = True,
    up: str = "auto",
    skip_frames: int = 0,
) -> MotionDatabase:
    """Read every ``*.bvh`` in ``folder`` (sorted by name) with its labels, each clip without
    a leading pose it jumps out of (:func:`drop_leading_pose`).

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
        raise MissingInputError(f"motion folder {folder} does not exist")
    contents, styles = _label_names(folder, "content"), _label_names(folder, "style")
    trials = read_trials(folder)
    files = sorted(folder.glob("*.bvh"))
    if not files:
        raise MissingInputError(f"no .bvh files in {folder}")
    chosen = []
    for f in files:
        lab = read_labels(f, contents, styles, trials)
        if content and lab.get("content") not in content:
            continue
        if style and lab.get("style") not in style:
            continue
        chosen.append((f, lab))
    chosen = [chosen[i] for i in spread(len(chosen), limit)]
    clips = [drop_leading_pose(read_motion_cached(f, up=up, skip_frames=skip_frames))
             for f, _ in tqdm(chosen, desc=f"loading {folder.name}", disable=not progress,
                              unit="clip")]
    return MotionDatabase(clips, [lab for _, lab in chosen])


def _same_skeleton(a, b) -> bool:
    return a is b or (a.names == b.names and np.array_equal(a.parents, b.parents)
                      and np.allclose(a.offsets, b.offsets, atol=1e-6))


def combine(dbs: Sequence[MotionDatabase], progress: bool = False) -> MotionDatabase:
    """One database on the first database's skeleton and frame rate (its first clip's):
    clips on other skeletons are retargeted (:func:`imuloco.core.retarget.retarget`; each
    other skeleton's rig is measured on all its clips, the target's on the first
    database's), every clip is resampled (:func:`imuloco.core.retarget.resampled`)."""
    first = dbs[0]
    target = first.skeleton
    fps = float(first.clips[0].fps)
    clips = [c for db in dbs for c in db.clips]
    labels = [dict(lab) for db in dbs for lab in db.labels]
    groups: list[list[int]] = []  # clips by skeleton
    for i, c in enumerate(clips):
        g = next((g for g in groups if _same_skeleton(clips[g[0]].skeleton, c.skeleton)), None)
        if g is None:
            groups.append([i])
        else:
            g.append(i)
    target_rig = None
    out: list[Motion] = list(clips)
    for g in tqdm(groups, desc="retargeting", disable=not progress or len(groups) < 2,
                  unit="skeleton"):
        sk = clips[g[0]].skeleton
        source_rig = None
        if not same_family(sk, target):
            if target_rig is None:
                target_rig = Rig.measure(first.clips[:: max(1, len(first) // 20)],
                                         where=labels[0].get("dataset", "training data"))
            source_rig = Rig.measure([clips[i] for i in g], where=f"{labels[g[0]]['name']}")
        for i in g:
            c = resampled(clips[i], fps)
            if not _same_skeleton(sk, target):
                c = retarget(c, target if source_rig is None else target_rig, source_rig)
            out[i] = c
    return MotionDatabase(out, labels)


def load_databases(folders: Sequence[str | Path], limit: int | None = None,
                   progress: bool = True, up: str = "auto", skip_frames: int = 0
                   ) -> MotionDatabase:
    """The clips of several folders as one database (:func:`combine`); ``limit`` and the
    reading options apply to each folder."""
    dbs = [load_database(f, limit=limit, progress=progress, up=up, skip_frames=skip_frames)
           for f in folders]
    return dbs[0] if len(dbs) == 1 else combine(dbs, progress=progress)


def load_sample(progress: bool = False) -> MotionDatabase:
    """The small sample bundled with the package (16 clips, see ``data/sample/README.md``)."""
    return load_database(SAMPLE_DIR, progress=progress)
