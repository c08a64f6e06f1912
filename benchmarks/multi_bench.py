"""Model files reading several sensors against the one-sensor model and the mean pose, per body
part, on clips they never saw; nothing is retrained (issue 46: score a shipped-style model
while or after it trains).

    python benchmarks/multi_bench.py --models MULTI.npz,shipped [--data ../shared/data] \
        [--sets validation,heldout-styles,actions,cmu] [--limit N] [--list] [-o FILE.md]

``--models``: model files, comma separated; ``shipped`` is the shipped ``learned`` model of
the first model's first placement. Every test clip is simulated once with the union of the
models' sensors (`phone` noise, test seed 1000, the first model's placements first) and each
model reads its own sensors' columns of those signals: the shin a two-sensor model reads is
the very shin the one-sensor model reads. Measured as ``imuloco bench`` measures a test clip
(:func:`imuloco.lab.bench.measure`): MPJPE and the legs, arms and trunk groups
(:data:`imuloco.core.bodymap.PART_GROUPS`), cm, frame-weighted.

Which clips a model never saw is read from its file: its protocol's ``data`` (the training
folders), ``split`` (``imuloco train --split``: ``heldout-styles`` leaves the exhausted and
feminine clips out, ``random-clips`` its test fifth) and ``validation`` (``learned`` holds
that share of its clips out by name for its validation curve,
:func:`imuloco.methods.training.held_out`). A set's clips are those of its folders that
**no** model saw:

- ``validation``: ``bandai-namco-2`` and ``bandai-namco-1``;
- ``heldout-styles``: the exhausted and feminine clips of the four Bandai-Namco folders;
- ``actions``: ``bandai-namco-1-actions`` and ``bandai-namco-2-actions``;
- ``cmu``: ``cmu-iclone`` on its own rig, scored on body parts against its truth retargeted
  onto the training skeleton (``bench --split cross-dataset``'s ``*_retargeted_cm``).

``--seen-by-others`` takes the clips the first model never saw even when another model saw
them (its rows are then marked "saw k"): the shipped one-sensor model was trained on nearly
every clip, so without a one-sensor model trained on the same split as the first, it is
in-sample there. The mean pose is ``mean`` fitted on at most 200 ``bandai-namco-2`` clips no
set tests.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from imuloco.app.pipeline import shipped_model
from imuloco.core.motion import MotionDatabase
from imuloco.core.retarget import resampled
from imuloco.io.atomic import atomic_write_text, check_output
from imuloco.io.database import load_database, spread
from imuloco.lab.bench import aggregate, measure, truth_on_training_rig
from imuloco.lab.protocols import HELDOUT_STYLES, in_random_test
from imuloco.methods import get_method, load_model
from imuloco.methods.training import Example, held_out, synthesize

SEED = 1000
BANDAI = ("bandai-namco-2", "bandai-namco-1", "bandai-namco-1-actions", "bandai-namco-2-actions")
SETS = {"validation": BANDAI[:2], "heldout-styles": BANDAI, "actions": BANDAI[2:],
        "cmu": ("cmu-iclone",)}
KEYS = ("mpjpe_cm", "legs_cm", "arms_cm", "trunk_cm")
CROSS_KEYS = ("mpjpe_retargeted_cm", "legs_retargeted_cm", "arms_retargeted_cm",
              "trunk_retargeted_cm")


def saw(model, labels: dict) -> bool:
    """Whether ``model`` was trained on the clip of ``labels`` (its folder in ``dataset``)."""
    protocol = getattr(model, "protocol_", None) or {}
    data = protocol.get("data")
    if not data:
        raise SystemExit(f"{model.name}: its file does not say what it was trained on")
    if labels["dataset"] not in data.split("+"):
        return False
    split = protocol.get("split") or "all"
    if split == "heldout-styles" and labels.get("style") in HELDOUT_STYLES:
        return False
    if split == "random-clips" and in_random_test(labels["name"]):
        return False
    if split not in ("all", "heldout-styles", "random-clips"):
        raise SystemExit(f"{model.name}: trained on split {split!r}, which this script cannot "
                         "tell the clips of")
    return not held_out(labels["name"], float(model.get_params().get("validation", 0.0)))


def columns(model, placements: list[str]) -> np.ndarray:
    """Indices of ``model``'s sensors' 6 channels each in signals of ``placements``."""
    return np.concatenate([np.arange(6) + 6 * placements.index(p) for p in model.placements_])


def unseen(set_name: str, folders: dict[str, MotionDatabase], judges: list,
           limit: int | None) -> MotionDatabase | None:
    """The clips of set ``set_name`` (module docstring) that none of ``judges`` saw (at most
    ``limit``, spread over them); None when there are none."""
    clips, labels = [], []
    for f in SETS[set_name]:
        for c, lab in zip(folders[f].clips, folders[f].labels):
            if set_name == "heldout-styles" and lab.get("style") not in HELDOUT_STYLES:
                continue
            if not any(saw(m, lab) for m in judges):
                clips.append(c)
                labels.append(lab)
    if not clips:
        return None
    db = MotionDatabase(clips, labels)
    return db.subset(spread(len(db), limit)) if limit else db


def load_models(spec: str) -> dict:
    models = {}
    for name in spec.split(","):
        if name == "shipped":
            first = next(iter(models.values())).placements_[0] if models else "right_ankle"
            path = Path(shipped_model("learned", first))
            models[f"shipped {path.name}"] = load_model(path)
        else:
            models[Path(name).name] = load_model(name)
    return models


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--models", required=True)
    ap.add_argument("--data", type=Path, default=Path("../shared/data"))
    ap.add_argument("--sets", default=",".join(SETS))
    ap.add_argument("--limit", type=int, default=None, help="at most N clips a set (spread)")
    ap.add_argument("--seen-by-others", action="store_true")
    ap.add_argument("--list", action="store_true", help="print each set's clip names")
    ap.add_argument("-o", "--output", type=Path, default=None)
    args = ap.parse_args()
    if args.output is not None:
        check_output(args.output)
    sets = args.sets.split(",")
    if set(sets) - set(SETS):
        raise SystemExit(f"unknown set(s) {sorted(set(sets) - set(SETS))}; choose from "
                         f"{list(SETS)}")
    models = load_models(args.models)
    first = next(iter(models.values()))
    judges = [first] if args.seen_by_others else list(models.values())
    placements = list(dict.fromkeys(p for m in models.values() for p in m.placements_))
    lines = ["Models:"]
    for n, m in models.items():
        p = m.protocol_ or {}
        lines.append(f"- {n}: reads {'+'.join(m.placements_)}; trained on {p.get('data')}, "
                     f"split {p.get('split') or 'all'}, holding out "
                     f"{m.get_params().get('validation', 0.0):g} of its clips by name")
    lines += ["", (f"Test signals: {'+'.join(placements)} simulated once per clip, phone "
                   f"noise, seed {SEED}. A set's clips: those no model saw"
                   + (f" ({next(iter(models))} only)." if args.seen_by_others else ".")), ""]

    folders = {f: load_database(args.data / f, progress=False)
               for f in dict.fromkeys(f for s in sets for f in SETS[s])}
    train_db = (folders["bandai-namco-2"] if "bandai-namco-2" in folders
                else load_database(args.data / "bandai-namco-2", progress=False))
    tested = {s: unseen(s, folders, judges, args.limit) for s in sets}
    names = {lab["name"] for db in tested.values() if db is not None for lab in db.labels}
    rest = [i for i, lab in enumerate(train_db.labels) if lab["name"] not in names]
    mean = get_method("mean").fit(train_db.subset([rest[i] for i in spread(len(rest), 200)]),
                                  placements[:1], "phone", 0)
    for set_name, db in tested.items():
        if db is None:
            lines += [(f"## {set_name}: no clip of {', '.join(SETS[set_name])} that no model "
                      "saw"), ""]
            continue
        cross = set_name == "cmu"
        keys = CROSS_KEYS if cross else KEYS
        truths = None
        if cross:
            fps = float(train_db.clips[0].fps)
            db = MotionDatabase([resampled(c, fps) for c in db.clips], db.labels)
            truths = truth_on_training_rig(train_db, db)
        lines += [(f"## {set_name}: {len(db)} clips, {sum(c.num_frames for c in db.clips):,} "
                  "frames"), ""]
        if args.list:
            lines += [", ".join(lab["name"] for lab in db.labels), ""]
        lines += ["| model | sensors | MPJPE | legs | arms | trunk |",
                  "|---|---|---:|---:|---:|---:|"]
        ex = synthesize(db, placements, "phone", SEED)
        rows = {}
        for n, m in [*models.items(), ("mean pose", mean)]:
            own = [Example(e.motion, e.signals[:, columns(m, placements)], e.labels) for e in ex]
            rows[n] = a = aggregate(measure(m, own, truths=truths)["clips"])
            seen = 0 if m is mean else sum(saw(m, lab) for lab in db.labels)
            sensors = "none" if m is mean else "+".join(m.placements_)
            lines.append(f"| {n}{f' (saw {seen})' if seen else ''} | {sensors} | "
                         + " | ".join(f"{a[k]:.2f}" for k in keys) + " |")
            print(lines[-1], flush=True)
        head = next(iter(models))
        for o in list(models)[1:]:
            lines += ["", f"{head} / {o}: " + ", ".join(
                f"{k.split('_')[0]} {rows[head][k] / rows[o][k]:.2f}" for k in keys)]
        lines.append("")
    text = "\n".join(lines)
    print(text)
    if args.output is not None:
        atomic_write_text(args.output, text + "\n")


if __name__ == "__main__":
    main()
