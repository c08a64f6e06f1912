"""``reconstruct``'s outputs for animation tools: ``--rig``, glTF by suffix, unknown suffixes
refused (imuloco.app.export through the command line)."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from imuloco.cli import cli
from imuloco.io.bvh import read_bvh, write_bvh
from imuloco.io.database import load_sample
from imuloco.io.sensorlog import write_generic_csv
from imuloco.sensors.simulate import simulate


@pytest.fixture(scope="module")
def args(tmp_path_factory, sample_db, ridge_without_demo_clip):
    """``reconstruct LOG --model RIDGE --no-calibrate`` of a simulated phone on the shin."""
    folder = tmp_path_factory.mktemp("export")
    walk = next(c for c in sample_db.clips if "walk" in c.name)
    log = write_generic_csv(simulate(walk, ["right_ankle"], 100.0, "phone", seed=3),
                            folder / "walk.csv")
    model = ridge_without_demo_clip.save(folder / "ridge.npz")
    return ["reconstruct", str(log), "--model", str(model), "--no-calibrate"]


def test_unknown_suffixes_are_refused_before_any_work(tmp_path, args):
    """``-o x.fbx`` wrote BVH text into x.fbx, ``--report a.md`` JSON: now each is one clear
    error line and nothing is written."""
    res = CliRunner().invoke(cli, [*args, "-o", str(tmp_path / "x.fbx")])
    assert res.exit_code == 1 and "x.fbx" in res.output
    assert ".bvh, .glb, .gltf" in res.output, res.output
    res = CliRunner().invoke(cli, [*args, "-o", str(tmp_path / "w.bvh"), "--report",
                                   str(tmp_path / "a.md")])
    assert res.exit_code == 1 and "a.md" in res.output and ".json" in res.output, res.output
    skeleton = _sample_bvh(tmp_path)
    res = CliRunner().invoke(cli, [*args, "-o", str(tmp_path / "w.bvh"), "--rig", "unity",
                                   "--skeleton", str(skeleton)])
    assert res.exit_code == 2 and "exclusive" in res.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.bvh"]


def _sample_bvh(tmp_path):
    """A BVH of the sample's rig (a --skeleton)."""
    return write_bvh(load_sample().clips[0].slice(0, 2), tmp_path / "s.bvh")


def test_reconstruct_writes_a_t_pose_bvh_by_default_and_glb_on_a_preset(tmp_path, args):
    """The default BVH rests in a T-pose (legs straight down), ``--rig model`` as before
    (every bone along +X), the same world positions in both (1e-5 m, the file's rounding);
    ``-o walk.glb --rig unity`` is glTF with Unity's bone names."""
    pygltflib = pytest.importorskip("pygltflib")
    for name, extra in (("tpose.bvh", []), ("model.bvh", ["--rig", "model"]),
                        ("walk.glb", ["--rig", "unity"])):
        res = CliRunner().invoke(cli, [*args, "-o", str(tmp_path / name), *extra])
        assert res.exit_code == 0, res.output
    tpose, model = read_bvh(tmp_path / "tpose.bvh"), read_bvh(tmp_path / "model.bvh")
    assert tpose.skeleton.names == model.skeleton.names
    np.testing.assert_allclose(tpose.positions(), model.positions(), atol=1e-5, rtol=0)
    knee = tpose.skeleton.part("left_knee")
    assert tpose.skeleton.offsets[knee] @ [0, -1, 0] == pytest.approx(
        np.linalg.norm(tpose.skeleton.offsets[knee]), rel=1e-3)  # straight down
    np.testing.assert_allclose(model.skeleton.offsets[knee] @ [0, 1, 1], 0.0, atol=1e-6)  # +X
    g = pygltflib.GLTF2().load(str(tmp_path / "walk.glb"))
    names = {n.name for n in g.nodes}
    assert {"Hips", "LeftUpperArm", "RightLowerLeg", "LeftToes"} <= names
    assert len(g.animations[0].channels) == tpose.skeleton.num_joints + 1


def _rest_height_bvh(path) -> float:
    """The figure's height at rest in a BVH, as Blender shows it: from the lowest to the
    highest joint or End Site (rotations zero, the hierarchy's offsets alone)."""
    from imuloco.ops.kinematics import fk
    sk = read_bvh(path).skeleton
    _, pos = fk(np.tile([0.0, 0.0, 0.0, 1.0], (sk.num_joints, 1)), np.zeros(3), sk.offsets,
                sk.parents)
    ends = [pos[j] + e for j, e in sk.end_sites.items()]
    return float(np.ptp(np.concatenate([pos, ends])[:, 1]))


def _rest_height_gltf(path) -> float:
    """The same in a glTF: every node of the skin (joints and their ``_end`` tips) placed by
    the node tree's rest translations (a bind pose without rotations)."""
    pygltflib = pytest.importorskip("pygltflib")
    g = pygltflib.GLTF2().load(str(path))
    heights, stack = [], [(g.skins[0].skeleton, 0.0)]
    while stack:
        i, above = stack.pop()
        node = g.nodes[i]
        assert node.rotation in (None, [0, 0, 0, 1])
        y = above + (node.translation or [0.0, 0.0, 0.0])[1]
        heights.append(y)
        stack += [(c, y) for c in node.children or [] if c in g.skins[0].joints]
    return float(np.ptp(heights))


@pytest.mark.parametrize("name, extra, read", [
    ("walk.bvh", [], _rest_height_bvh),
    ("mixamo.bvh", ["--rig", "mixamo", "--units", "m"], _rest_height_bvh),
    ("pieces.bvh", ["--piece-seconds", "10"], _rest_height_bvh),
    ("walk.glb", ["--rig", "unity"], _rest_height_gltf)])
def test_the_figure_at_rest_is_as_tall_as_height(tmp_path, args, name, extra, read):
    """``--height H``: the written file's T-pose figure, head top (head joint and its End
    Site) to the feet, is H tall (read back from the file; the issue's target: within 2 %;
    before, the BVH's head End Site was a rule of thumb, 0.2 % short on this rig and a
    posed figure in Blender several % short)."""
    res = CliRunner().invoke(cli, [*args, "-o", str(tmp_path / name), "--height", "1.62",
                                   *extra])
    assert res.exit_code == 0, res.output
    assert read(tmp_path / name) == pytest.approx(1.62, abs=1e-3)
