"""Per-part errors of models trained with ``--split heldout-styles`` on the five shared
folders (issue 46: what a second sensor buys), against the mean pose fitted on the same
training part, on the held-out styles (``exhausted``, ``feminine``): all clips, locomotion and
actions. Clips a model refuses (a foot sensor needs strides) are left out for it and for its
mean pose alike. The table of ``docs/results/multi/README.md``.

    python benchmarks/multi_heldout_styles.py hs_right_ankle.npz hs_right_ankle+left_wrist.npz

(``benchmarks/multi_bench.py`` scores saved models on the clips none of them saw, for models
trained on other splits.)
"""
import sys
from pathlib import Path

from imuloco.errors import InputError
from imuloco.lab.bench import aggregate, load_data, measure
from imuloco.lab.protocols import HELDOUT_ACTIONS, split
from imuloco.methods import get_method, load_model
from imuloco.methods.training import synthesize

D = Path(__file__).resolve().parents[2] / "shared" / "data"
FOLDERS = [D / f for f in ("bandai-namco-2", "bandai-namco-1", "cmu-iclone",
                           "bandai-namco-1-actions", "bandai-namco-2-actions")]
KEYS = ("mpjpe_cm", "legs_cm", "arms_cm", "trunk_cm", "foot_skate_cm_s", "foot_skate_gt_cm_s")

train, test = split(load_data(FOLDERS), "heldout-styles")
print(f"training part {len(train)} clips, held-out styles {len(test)}", flush=True)
for path in sys.argv[1:]:
    model = load_model(path)
    placements = list(model.placements_)
    examples = synthesize(test, placements, "phone", 1000)
    ok, model_clips, refused = [], [], []
    for ex in examples:
        try:
            model_clips += measure(model, [ex])["clips"]
            ok.append(ex)
        except InputError:
            refused.append(ex.labels["name"])
    print(f"{path}: {len(refused)} clips refused {refused[:4]}", flush=True)
    mean_clips = measure(get_method("mean").fit(train, placements, "phone", 0), ok)["clips"]
    for name, clips in (("mean pose", mean_clips), (Path(path).stem, model_clips)):
        for group, pick in (("all", clips),
                            ("actions", [c for c in clips if c["motion_type"] in HELDOUT_ACTIONS])):
            if pick:
                a = aggregate(pick)
                row = ", ".join(f"{k} {a[k]:.2f}" for k in KEYS if a[k] is not None)
                print(f"  {name} / {group} ({len(pick)} clips): {row}", flush=True)
