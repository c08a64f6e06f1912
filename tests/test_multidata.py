"""Labels from trials.csv, a converter's leading pose, several folders as one training set,
and the protocols that use them (heldout-contents, cross-dataset, --seeds)."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner
from tests.test_retarget import other_rig

from imuloco.cli import cli
from imuloco.core.motion import Motion
from imuloco.core.retarget import resampled
from imuloco.core.skeleton import Skeleton
from imuloco.errors import FormatError
from imuloco.io.bvh import write_bvh
from imuloco.io.database import (
    content_of,
    drop_leading_pose,
    load_database,
    load_databases,
    load_sample,
)
from imuloco.lab.bench import run_bench
from imuloco.lab.protocols import folds
from imuloco.measures.metrics import (
    GROUP_RETARGETED_KEYS,
    METRIC_KEYS,
    RETARGETED_KEYS,
    evaluate_parts,
    evaluate_parts_curves,
)


@pytest.fixture(scope="module")
def sample():
    return load_sample()


@pytest.fixture(scope="module")
def rig_folder(sample, tmp_path_factory):
    """Four sample clips on a Mixamo-named rig at 60 fps with a trials.csv, the first with a
    T-pose prepended (as the cmu-iclone converter does)."""
    folder = tmp_path_factory.mktemp("other-lab")
    rows = ["file,subject,trial,description"]
    descriptions = ["walk", "run/jog", "slow walk", "basketball - backward dribble"]
    for k, c in enumerate(sample.clips[::4]):
        m = resampled(other_rig(c, 1.15), 60.0)
        if k == 0:
            tpose = np.tile([0.0, 0.0, 0.0, 1.0], (1, m.skeleton.num_joints, 1))
            m = Motion(m.skeleton, np.concatenate([tpose, m.rotations]),
                       np.concatenate([m.root[:1], m.root]), m.fps)
        write_bvh(m, folder / f"{k:03d}_01.bvh")
        rows.append(f'{k:03d}_01.bvh,{k + 2},1,"{descriptions[k]}"')
    (folder / "trials.csv").write_text("\n".join(rows) + "\n")
    return folder


def test_descriptions_map_to_contents():
    assert content_of("walk") == "walk" and content_of("slow walk") == "walk"
    assert content_of("run/jog") == "run" and content_of("jump, balance") == "jump"
    assert content_of("walk on uneven terrain") == "walk-uneven"
    assert content_of("basketball - forward dribble, 90-degree left turns") == \
        "dribble-turn-left"
    assert content_of("basketball - sideways dribble") == "dribble-side"
    assert content_of("juggling") is None


def test_a_folder_with_trials_csv_is_labelled_and_loses_its_tpose(rig_folder):
    db = load_database(rig_folder, progress=False)
    assert [lab["content"] for lab in db.labels] == ["walk", "run", "walk", "dribble-back"]
    assert [lab["subject"] for lab in db.labels] == ["2", "3", "4", "5"]
    assert db.labels[2]["style"] == "slow" and db.labels[0]["dataset"] == rig_folder.name
    from imuloco.io.bvh import read_bvh

    first = read_bvh(rig_folder / "000_01.bvh")
    assert db.clips[0].num_frames == first.num_frames - 1  # the T-pose is gone
    assert drop_leading_pose(db.clips[0]).num_frames == db.clips[0].num_frames  # once only


def test_trials_csv_without_its_columns_is_refused(tmp_path, sample):
    write_bvh(sample.clips[0], tmp_path / "a.bvh")
    (tmp_path / "trials.csv").write_text("name,what\na.bvh,walk\n")
    with pytest.raises(FormatError, match=r"trials\.csv:1.*'file' and 'description'"):
        load_database(tmp_path, progress=False)


def test_several_folders_become_one_set_on_the_first_skeleton(rig_folder):
    from imuloco.data import SAMPLE_DIR

    db = load_databases([SAMPLE_DIR, rig_folder], progress=False)
    assert len(db) == 20
    first = db.clips[0].skeleton
    assert all(c.skeleton.names == first.names for c in db.clips)
    assert all(c.fps == 30.0 for c in db.clips)
    assert {lab["dataset"] for lab in db.labels} == {"sample", rig_folder.name}
    # a retargeted clip moves as the sample clip it was made from (rig_folder's second)
    from imuloco.measures.metrics import mpjpe

    orig, back = load_sample().clips[4], db.clips[17]
    assert back.num_frames == orig.num_frames
    assert mpjpe(orig, back) < 2.0


def test_evaluate_parts_compares_skeletons_that_differ(sample):
    c = sample.clips[0]
    other = other_rig(c, 1.3)
    values = evaluate_parts(other, c)  # the same movement on a 1.3 times larger rig
    assert set(values) == set(METRIC_KEYS)
    assert values["mpjpe_cm"] < 1e-6 and values["path_err_cm"] < 1e-6
    assert values["angle_deg"] is None and values["dpv"] is None
    assert values["jitter"] == pytest.approx(values["jitter_gt"], rel=1e-6)
    assert all(values[k] is None for k in (*RETARGETED_KEYS, *GROUP_RETARGETED_KEYS))


def longer_armed(c: Motion) -> Motion:
    """``c`` on another rig 1.3 times larger, with arms a further 1.3 times longer, moving
    alike: a body of other proportions."""
    o = other_rig(c, 1.3)
    arms = [i for i, n in enumerate(o.skeleton.names) if "Arm" in n or "Hand" in n]
    offsets = o.skeleton.offsets.copy()
    offsets[arms] *= 1.3
    return Motion(Skeleton(o.skeleton.names, o.skeleton.parents, offsets), o.rotations,
                  o.root, o.fps)


def test_evaluate_parts_also_scores_against_the_retargeted_truth(sample):
    c = sample.clips[0]
    other = other_rig(c, 1.3)
    moved = Motion(c.skeleton, c.rotations[::-1].copy(), c.root, c.fps)  # another motion
    values = evaluate_parts(other, moved, retargeted=c)
    assert values["mpjpe_retargeted_cm"] > 1.0
    # the same error, measured on the 1.3 times larger body's scale or on the truth's own
    assert values["mpjpe_cm"] == pytest.approx(1.3 * values["mpjpe_retargeted_cm"], rel=1e-6)
    longer = longer_armed(c)
    perfect = evaluate_parts(longer, c, retargeted=c)
    assert perfect["mpjpe_cm"] > 0.5  # the other body's proportions: a floor above zero
    assert perfect["mpjpe_retargeted_cm"] < 1e-6
    assert perfect["upper_retargeted_cm"] < 1e-6 and perfect["lower_retargeted_cm"] < 1e-6
    # legs, arms, trunk too: the long arms' floor shows against the own truth only
    assert perfect["arms_cm"] > 1.0 and perfect["legs_cm"] < 1e-6
    assert max(perfect[f"{g}_retargeted_cm"] for g in ("legs", "arms", "trunk")) < 1e-6
    for g in ("legs", "arms", "trunk"):
        assert values[f"{g}_cm"] == pytest.approx(1.3 * values[f"{g}_retargeted_cm"], rel=1e-6)


def test_evaluate_parts_curves_are_the_rms_errors_its_metrics_average(sample):
    c = sample.clips[0]
    other = other_rig(c, 1.3)
    moved = Motion(c.skeleton, c.rotations[::-1].copy(), c.root, c.fps)  # another motion
    values, actual, against = evaluate_parts_curves(other, moved, retargeted=c)
    assert values == evaluate_parts(other, moved, retargeted=c)
    assert actual.shape == (c.num_frames,)
    assert actual.mean() * 100 == pytest.approx(values["rmse_cm"], rel=1e-12)
    assert actual == pytest.approx(1.3 * against, rel=1e-6)  # the larger body's scale
    assert evaluate_parts_curves(other, moved)[2] is None


def test_cross_dataset_confidence_rows_also_hold_the_error_against_the_retargeted_truth(sample):
    """A reconstruction equal to the truth on the training rig: its confidence rows' actual
    error on the other rig's parts is the proportions' floor, against the retargeted truth
    zero."""
    from imuloco.lab.bench import measure
    from imuloco.lab.confidence import check
    from imuloco.methods.base import Reconstruction
    from imuloco.methods.training import Example

    c = sample.clips[0]
    longer = longer_armed(c)

    class Perfect:
        name = "perfect"

        def reconstruct_signals_full(self, signals):
            n = len(signals)
            return Reconstruction(c, np.full(n, 0.05), np.zeros(n, bool), "",
                                  {"sigma_m": np.full(n, 0.05)})

    ex = Example(longer, np.zeros((c.num_frames, 6)), {"name": "a", "content": "walk"})
    (rows,) = measure(Perfect(), [ex], truths={"a": c})["confidence"]
    assert rows["actual_m"].mean() > 0.005 and rows["actual_retargeted_m"].max() < 1e-8
    (t, _all) = check(rows, actual="actual_retargeted_m")
    assert t["actual_cm"] < 1e-6 and t["predicted_cm"] == pytest.approx(5.0)


def test_heldout_contents_has_a_fold_per_content(sample):
    out = folds(sample, "heldout-contents")
    assert [f for f, _, _ in out] == ["walk", "walk-turn-left", "walk-turn-right", "run"]
    for fold, train, test in out:
        assert {lab["content"] for lab in test.labels} == {fold}
        assert fold not in {lab["content"] for lab in train.labels}
        assert len(train) + len(test) == len(sample)


def test_seeds_give_mean_and_spread(tmp_path):
    recs = run_bench(["ridge"], "heldout-contents", limit=8, seeds=2, out=tmp_path)
    total = next(r for r in recs if r["motion_type"] == "all")
    assert total["seeds"] == [0, 1] and len(total["mpjpe_cm_per_seed"]) == 2
    assert total["mpjpe_cm"] == pytest.approx(np.mean(total["mpjpe_cm_per_seed"]))
    assert total["mpjpe_cm_std"] == pytest.approx(np.std(total["mpjpe_cm_per_seed"], ddof=1))
    assert total["mpjpe_cm_std"] > 0  # the training noise differs between seeds
    assert [r["motion_type"] for r in recs] == ["walk", "walk-turn-left", "walk-turn-right",
                                                "run", "all"]
    assert "±" in (tmp_path / "results.md").read_text()


def test_cross_dataset_from_the_command_line(rig_folder, tmp_path):
    from imuloco.data import SAMPLE_DIR

    res = CliRunner().invoke(cli, ["bench", "--method", "mean", "--split", "cross-dataset",
                                   "--train", str(SAMPLE_DIR), "--test", str(rig_folder),
                                   "--out", str(tmp_path)])
    assert res.exit_code == 0, res.output
    import json

    recs = json.loads((tmp_path / "results.json").read_text())
    total = next(r for r in recs if r["motion_type"] == "all")
    assert total["data"] == f"sample -> {rig_folder.name}" and total["n_clips"] == 4
    assert total["angle_deg"] is None and 3 < total["mpjpe_cm"] < 30
    assert 3 < total["mpjpe_retargeted_cm"] < 30
    assert "retargeted onto the training skeleton" in (tmp_path / "results.md").read_text()
    res = CliRunner().invoke(cli, ["bench", "--method", "mean", "--split", "cross-dataset",
                                   "--out", str(tmp_path / "x")])
    assert res.exit_code != 0 and "--train" in res.output


def test_the_truth_on_the_training_rig_is_the_motion_the_test_clip_was_made_from(
        sample, rig_folder):
    from imuloco.lab.bench import truth_on_training_rig
    from imuloco.measures.metrics import mpjpe

    test = load_database(rig_folder, progress=False)
    test = type(test)([resampled(c, 30.0) for c in test.clips], test.labels)
    truths = truth_on_training_rig(sample, test)
    assert list(truths) == [lab["name"] for lab in test.labels]
    made_from = sample.clips[4]  # rig_folder's second clip (the first lost its T-pose)
    moved = truths[test.labels[1]["name"]]
    assert moved.skeleton.names == made_from.skeleton.names
    assert moved.num_frames == made_from.num_frames and mpjpe(made_from, moved) < 2.0
    assert mpjpe(sample.clips[8], truths[test.labels[2]["name"]]) < 2.0


def test_heldout_actions_leaves_each_action_out_and_trains_on_walking_too(sample):
    """Relabel two sample clips as actions: each is a fold of its own, trained on every other
    clip (the walks included); data without any action content is refused by name."""
    from imuloco.errors import InputError

    db = sample.subset(list(range(len(sample))))
    db.labels[0] = {**db.labels[0], "content": "bow"}
    db.labels[1] = {**db.labels[1], "content": "wave-left-hand"}
    out = folds(db, "heldout-actions")
    assert [f for f, _, _ in out] == ["bow", "wave-left-hand"]
    for fold, train, test in out:
        assert [lab["content"] for lab in test.labels] == [fold]
        assert len(train) == len(db) - 1 and "walk" in {lab["content"] for lab in train.labels}
    with pytest.raises(InputError, match="heldout-actions needs clips of one of"):
        folds(sample, "heldout-actions")


def test_body_part_groups_score_only_their_parts(sample):
    """Arms moved away, legs and trunk untouched: only ``arms_cm`` rises, by the shift."""
    from imuloco.measures.metrics import evaluate
    from imuloco.ops.rotations import about_y, qmul

    gt = sample.clips[0]
    rec = gt.copy()
    for side in ("left", "right"):
        j = gt.skeleton.part(f"{side}_shoulder")  # turn the whole arm about the vertical
        rec.rotations[:, j] = qmul(rec.rotations[:, j], about_y(np.full(gt.num_frames, 0.5)))
    v = evaluate(gt, rec)
    assert v["legs_cm"] == pytest.approx(0, abs=1e-9)
    assert v["trunk_cm"] == pytest.approx(0, abs=1e-9)
    assert v["arms_cm"] > 1.0
