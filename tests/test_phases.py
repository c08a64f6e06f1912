"""Foot contacts, crossing events, steps and gait phases."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest

from imuloco.core.motion import Motion
from imuloco.ops.rotations import about_y, from_rotvec, qmul, qrot
from imuloco.phases import (
    EOM2014,
    GAIT8,
    cadence,
    crossing_events,
    gait_phases,
    right_ahead,
    segment,
)
from imuloco.phases.contacts import (
    FEET,
    MIN_FLOOR_STEPS,
    clean_mask,
    foot_contacts,
    runs,
)
from imuloco.phases.gait import enforce_cycle, gait8_states

WALKS = ["walk", "walk-turn-left", "walk-turn-right"]
STANCE = {GAIT8.index(p) for p in ("IC", "LR", "MST", "TST", "PSW")}


def strike_sequence(g) -> str:
    ev = sorted([(int(f), "L") for f in g.steps["left"]] + [(int(f), "R") for f in g.steps["right"]])
    return "".join(s for _, s in ev)


def alternates(seq: str) -> bool:
    return len(seq) >= 2 and all(a != b for a, b in itertools.pairwise(seq))


# --- array functions ---------------------------------------------------------------------------

def test_clean_mask_fills_gaps_drops_blips_keeps_edges():
    m = np.array([1, 1, 0, 1, 1, 0, 0, 0, 1, 0, 0, 0, 1, 1], bool)
    out = clean_mask(m, max_gap=1, min_length=2)
    # the 1-frame gap is filled, the 1-frame blip dropped, the edge runs kept
    assert out.tolist() == [1, 1, 1, 1, 1, 0, 0, 0, 0, 0, 0, 0, 1, 1]
    both = clean_mask(np.stack([m, ~m], 1), 1, 2)
    assert np.array_equal(both[:, 0], out)


def test_crossing_hysteresis_ignores_chatter():
    t = np.arange(300)
    diff = 0.3 * np.sin(2 * np.pi * t / 100)  # three strides: a zero crossing every 50 frames
    diff += np.random.default_rng(0).normal(0, 0.005, t.size)
    ahead = right_ahead(diff, tol=0.02)
    ev = crossing_events(ahead)
    assert len(ev["right"]) + len(ev["left"]) == 5  # the one at frame 0 is not an event
    r = np.concatenate([ev["right"], ev["left"]]) % 50
    assert np.all(np.minimum(r, 50 - r) <= 3)  # within 3 frames of the true crossings
    assert np.all(ev["left"] % 100 > 45) and np.all(ev["right"] % 100 < 10)
    assert not right_ahead(np.zeros(5), 0.1).any()


def test_cadence_counts_intervals():
    # a strike every 15 frames at 30 fps: two steps a second
    assert cadence([np.array([0, 30, 60]), np.array([15, 45])], 30.0) == pytest.approx(120.0)
    assert np.isnan(cadence([np.array([3]), np.array([], int)], 30.0))


def test_gait8_states_follow_table1():
    # one idealised walking cycle of the right leg, frame by frame (RH, R, LH, L, right ahead)
    rows = [(1, 1, 0, 1, 1), (1, 1, 0, 0, 1), (1, 1, 0, 0, 0), (0, 1, 0, 0, 0), (0, 1, 1, 1, 0),
            (0, 0, 1, 1, 0), (0, 0, 1, 1, 1), (0, 0, 0, 1, 1)]
    a = np.array(rows, bool).T
    assert gait8_states(a[0], a[1], a[2], a[3], a[4]).tolist() == list(range(8))


def test_enforce_cycle_absorbs_short_backward_runs():
    lab = np.array([1, 1, 1, 2, 1, 2, 2, 3, 3, 7, 0, 0, 0, 0, 0, 0, 5, 5, 5, 5])
    out = enforce_cycle(lab, 8, min_back=3)
    # 2 -> 1 (1 frame) is absorbed; 3 -> 7 -> 0 is forward (wraps); 0 -> 5 (4 frames) is kept
    assert out.tolist() == [1, 1, 1, 2, 2, 2, 2, 3, 3, 7, 0, 0, 0, 0, 0, 0, 5, 5, 5, 5]


# --- the bundled sample ------------------------------------------------------------------------

@pytest.fixture(scope="module")
def sample_phases(sample_db):
    return [(m, lab, gait_phases(m)) for m, lab in sample_db]


def test_walking_heel_strikes_alternate(sample_phases):
    for m, lab, g in sample_phases:
        if lab["content"] in WALKS:
            assert alternates(strike_sequence(g)), (lab["name"], strike_sequence(g))


def test_cadence_physiological(sample_phases):
    walk = [g.cadence_spm for _, lab, g in sample_phases if lab["content"] in WALKS]
    run = [g.cadence_spm for _, lab, g in sample_phases if lab["content"] == "run"]
    assert all(80 <= c <= 140 for c in walk), walk
    # the "active" style runs in long bounds (about 130 spm); the others at 140-200
    assert all(120 <= c <= 200 for c in run), run
    assert np.median(run) > np.median(walk) + 20


def test_flight_in_running_not_in_walking(sample_phases):
    for m, lab, g in sample_phases:
        if lab["content"] == "run":
            assert g.flight.mean() > 0.15, lab["name"]
            assert g.labels("support")[0].tolist().count(0) < 0.05 * m.num_frames  # no double
        else:
            assert g.flight.mean() < 0.02, lab["name"]


def test_phases_cycle_and_match_contacts(sample_phases):
    for m, lab, g in sample_phases:
        segs = g.segments("gait8")
        assert segs[0][1] == 0 and segs[-1][2] == m.num_frames
        assert all(a[2] == b[1] for a, b in itertools.pairwise(segs))
        idx = [GAIT8.index(s[0]) for s in segs]
        assert all(1 <= (b - a) % 8 <= 4 for a, b in itertools.pairwise(idx)), (lab["name"], idx)
        stance = np.isin(g.phase, list(STANCE))
        assert np.mean(stance == g.contacts["right_foot"]) > 0.97, lab["name"]
        present = set(g.names())
        if lab["content"] in WALKS:  # a flat-footed (exhausted) walk may lack heel-off (TST)
            assert len(present) >= 7 and {"IC", "PSW"} <= present, (lab["name"], present)
        else:  # no double support while running: IC and PSW do not occur
            assert not present & {"IC", "PSW"}, (lab["name"], present)


def test_left_reference_mirrors_right(sample_db):
    m = sample_db.where(content="walk").clips[0]
    right, left = gait_phases(m), gait_phases(m, reference="left")
    assert np.mean(np.isin(left.phase, list(STANCE)) == left.contacts["left_foot"]) > 0.97
    # each leg's swing starts at its own toe-off
    for g, foot in ((right, "right"), (left, "left")):
        isw = [a for name, a, _ in g.segments() if name == "ISW" and a > 0]
        toe_off = np.flatnonzero(g.contacts[f"{foot}_foot"][:-1] & ~g.contacts[f"{foot}_foot"][1:])
        assert np.all(np.isin(isw, toe_off + 1))


def test_eom2014_steps_alternate(sample_phases):
    for m, lab, g in sample_phases:
        names = [s[0] for s in g.segments("eom2014")]
        steps = [n for n in names if n in ("left_step", "right_step")]
        assert all(a != b for a, b in itertools.pairwise(steps)), (lab["name"], names)
        assert set(names) <= set(EOM2014)


def _turned(m: Motion, q: np.ndarray, shift: np.ndarray | float = 0.0) -> Motion:
    """The whole motion ``m`` turned by the world rotation ``q`` (4,), then moved by ``shift``."""
    q = np.broadcast_to(q, (m.num_frames, 4))
    rot = m.rotations.copy()
    rot[:, 0] = qmul(q, rot[:, 0])
    return Motion(m.skeleton, rot, qrot(q, m.root) + shift, m.fps, m.name)


def _yawed(m: Motion, yaw: float, shift: np.ndarray) -> Motion:
    return _turned(m, about_y(np.array(yaw)), shift)


def test_contacts_and_phases_invariant_to_yaw_and_translation(sample_db):
    for m in (sample_db.where(content="walk-turn-left").clips[0],
              sample_db.where(content="run").clips[1]):
        g0 = gait_phases(m)
        g1 = gait_phases(_yawed(m, 2.1, np.array([3.0, 0.25, -7.0])))
        for k in g0.contacts:
            assert np.array_equal(g0.contacts[k], g1.contacts[k]), k
        assert np.array_equal(g0.phase, g1.phase)
        assert np.array_equal(g0.right_ahead, g1.right_ahead)


def test_thresholds_adapt_to_skeleton_size(sample_db):
    for m in (sample_db.where(content="walk").clips[1], sample_db.where(content="run").clips[0]):
        small = Motion(m.skeleton.scaled(0.5), m.rotations, m.root * 0.5, m.fps, m.name)
        c0, c1 = foot_contacts(m), foot_contacts(small)
        for k in c0:
            assert np.array_equal(c0[k], c1[k]), k
        assert np.array_equal(gait_phases(m).phase, gait_phases(small).phase)
        # the same absolute tolerances on the small skeleton would not see the same contacts
        assert any(not np.array_equal(c0[k], v) for k, v in
                   foot_contacts(small, heel_height_tol=0.04, toe_height_tol=0.1,
                                 speed_tol=1.6).items())


def _tilted(m: Motion, rise: float) -> Motion:
    """``m`` on a floor that rises ``rise`` metres from its first root position to the one
    farthest from it: the whole motion turned about the horizontal axis across that line."""
    ways = (m.root - m.root[0]) * [1.0, 0.0, 1.0]
    span = np.linalg.norm(ways, axis=-1).max()
    way = ways[np.argmax(np.linalg.norm(ways, axis=-1))]
    axis = np.cross(way / span, [0.0, 1.0, 0.0])
    return _turned(m, from_rotvec(axis * np.arctan2(rise, span)))


def _spells(mask: np.ndarray) -> np.ndarray:
    """(start, stop) of the True runs of a 1-D mask, shape (N, 2)."""
    starts, stops, vals = runs(mask)
    return np.stack([starts[vals], stops[vals]], axis=1)


def test_contacts_follow_a_sloping_floor(sample_db):
    """A floor rising 8 cm over the walk (as cmu-iclone's do) keeps the level clip's contacts
    within 2 frames; one floor level per clip loses the later steps' contacts."""
    for m in (sample_db.where(content="walk").clips[3],
              sample_db.where(content="walk-turn-left").clips[0]):
        flat, ramp = foot_contacts(m), _tilted(m, 0.08)
        c, level = foot_contacts(ramp), foot_contacts(ramp, sloped_floor=False)
        for k in flat:
            a, b = _spells(flat[k]), _spells(c[k])
            assert a.shape == b.shape and np.abs(a - b).max() <= 2, (m.name, k)
        for side in FEET:
            assert level[f"{side}_foot"].mean() < flat[f"{side}_foot"].mean() - 0.1, m.name


def test_floor_stays_level_where_little_ground_is_covered(sample_db):
    """Standing, or pacing to and fro over a leg length and a half: no slope is fitted (the
    floor is one level, as before), even on a tilted clip."""
    walk = sample_db.where(content="walk").clips[3]
    feet = walk.part_positions([f"{s}_ankle" for s in FEET])
    far = np.linalg.norm(feet[:, 0, [0, 2]] - feet[0, 0, [0, 2]], axis=-1)
    short = int(np.argmax(far > 1.5 * walk.skeleton.leg_length()))
    pace = np.tile(np.r_[np.arange(short), np.arange(short)[::-1]], 3)
    for frames in (pace, np.zeros(60, dtype=int)):
        m = Motion(walk.skeleton, walk.rotations[frames], walk.root[frames], walk.fps)
        for clip in (m, _tilted(m, 0.03) if frames.any() else m):
            c, level = foot_contacts(clip), foot_contacts(clip, sloped_floor=False)
            for k in c:
                assert np.array_equal(c[k], level[k]), k
        if frames.any():  # enough steps to fit a slope, were the ground covered wide enough
            assert sum(len(_spells(c[f"{s}_heel"])) for s in FEET) >= MIN_FLOOR_STEPS


def test_segment_api(sample_db):
    m = sample_db.clips[0]
    for kind in ("gait8", "eom2014", "support"):
        segs = segment(m, kind)
        assert sum(b - a for _, a, b in segs) == m.num_frames
    with pytest.raises(ValueError, match="unknown phase kind"):
        segment(m, "gait9")


def test_cli_phases_json(sample_db):
    from click.testing import CliRunner

    from imuloco.cli import cli
    from imuloco.data import SAMPLE_DIR

    f = SAMPLE_DIR / "dataset-2_run_normal_001.bvh"
    res = CliRunner().invoke(cli, ["phases", str(f), "--json"])
    assert res.exit_code == 0, res.output
    d = json.loads(res.output)
    t = d["frames"]
    assert d["fps"] == pytest.approx(30.0)
    assert set(d["contacts"]) == {"left_heel", "left_toe", "right_heel", "right_toe"}
    assert all(len(v) == t and set(v) <= {0, 1} for v in d["contacts"].values())
    assert len(d["phase"]) == t and set(d["phase"]) <= set(GAIT8)
    assert alternates("".join(s for _, s in sorted(
        [(f, "L") for f in d["steps"]["left"]] + [(f, "R") for f in d["steps"]["right"]])))
    assert 120 < d["cadence_spm"] < 200 and len(d["flight_frames"]) > 0.15 * t
    text = CliRunner().invoke(cli, ["phases", str(f)])
    assert text.exit_code == 0 and "cadence" in text.output


# --- shared data -------------------------------------------------------------------------------

@pytest.mark.shared
def test_shared_clips(shared_dir):
    from imuloco.io.bvh import read_bvh

    rng = np.random.default_rng(0)
    for content, n in (("walk", 5), ("walk-turn-left", 5), ("walk-turn-right", 5), ("run", 6)):
        files = sorted(shared_dir.glob(f"dataset-2_{content}_*.bvh"))
        for i in rng.choice(len(files), n, replace=False):
            f = files[i]
            g = gait_phases(read_bvh(f))
            assert alternates(strike_sequence(g)), f.name
            if content == "run":
                # the elderly style jogs with both feet briefly down and no flight at 30 fps
                assert 120 <= g.cadence_spm <= 200, f.name
                assert "_elderly_" in f.name or g.flight.any(), f.name
            else:
                assert 80 <= g.cadence_spm <= 150, f.name
                assert g.flight.mean() < 0.02, f.name


def test_positions_and_contacts_are_kept_until_the_motion_changes(sample_db):
    """A motion's fk and foot contacts are computed once and shared (read-only); changing its
    arrays, in place or by assignment, gets them computed again."""
    import pickle

    from imuloco.phases import foot_contacts

    m = sample_db.where(content="walk").clips[0].copy()
    pos, contacts = m.positions(), foot_contacts(m)
    assert m.positions() is pos and not pos.flags.writeable
    assert all(a is b for a, b in zip(foot_contacts(m).values(), contacts.values()))
    assert foot_contacts(m, speed_tol=0.5)["left_foot"] is not contacts["left_foot"]
    m.root[:, 1] += 0.5  # in place: the digest sees it
    moved = m.positions()
    assert moved is not pos
    np.testing.assert_allclose(moved[..., 1], pos[..., 1] + 0.5, atol=1e-12)
    again = foot_contacts(m)  # found again (the same: the floor rose with the feet)
    assert again["left_foot"] is not contacts["left_foot"]
    np.testing.assert_array_equal(again["left_foot"], contacts["left_foot"])
    m.rotations = m.rotations[::-1].copy()  # assigned
    assert not np.allclose(m.positions(), moved)
    np.testing.assert_array_equal(pickle.loads(pickle.dumps(m)).positions(), m.positions())
