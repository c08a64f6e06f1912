"""glTF 2.0 export (imuloco.io.gltf): read back by pygltflib and imported by Blender."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from imuloco.app.export import rest_of, write_reconstruction
from imuloco.core.rigs import apply_rig
from imuloco.errors import InputError, OutputExistsError
from imuloco.io.gltf import write_gltf
from imuloco.measures.gait import stature, to_height
from imuloco.ops.kinematics import fk

pygltflib = pytest.importorskip("pygltflib")

HEIGHT = 1.8
_DTYPES = {5126: "<f4", 5123: "<u2", 5125: "<u4"}
_WIDTH = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}


@pytest.fixture(scope="module")
def walk(sample_db):
    """The sample's walk at 1.8 m on the Mixamo preset, as ``reconstruct --rig mixamo``
    writes it."""
    clip = to_height(next(c for c in sample_db.clips if "walk" in c.name), HEIGHT)
    return apply_rig(clip, "mixamo", rest_of(clip))


def _read(path: Path):
    """The glTF at ``path`` (pygltflib) and a function decoding an accessor to an array."""
    g = pygltflib.GLTF2().load(str(path))
    blob = (g.binary_blob() if path.suffix == ".glb"
            else g.get_data_from_buffer_uri(g.buffers[0].uri))

    def accessor(k: int) -> np.ndarray:
        a = g.accessors[k]
        view = g.bufferViews[a.bufferView]
        width = _WIDTH[a.type]
        data = np.frombuffer(blob, _DTYPES[a.componentType], a.count * width,
                             view.byteOffset + (a.byteOffset or 0))
        return data.reshape(a.count, width).astype(np.float64)

    return g, accessor


@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_pygltflib_reads_back_the_skin_and_animation(walk, tmp_path: Path, suffix: str):
    """The file's skeleton, bind pose and sampled animation give our world joint positions
    (float32: within 1e-5 m), Y up in metres; sampler times are frame / fps; the mesh's
    vertices are skinned rigidly to the joints."""
    path = write_reconstruction(walk, tmp_path / f"w{suffix}", rig=None)
    g, accessor = _read(path)
    sk = walk.skeleton
    names = [n.name for n in g.nodes]
    assert names[:sk.num_joints] == sk.names
    assert {"mixamorig:Head_end", "mixamorig:LeftHand_end", "mixamorig:RightToeBase_end"} <= set(
        names)
    skin = g.skins[0]
    assert len(skin.joints) == sk.num_joints + 5 and skin.skeleton == 0
    # parents from the node tree; translations at rest; animated rotations and root path
    parents = np.full(sk.num_joints, -1)
    for i, node in enumerate(g.nodes[:sk.num_joints]):
        for c in node.children or []:
            if c < sk.num_joints:
                parents[c] = i
    np.testing.assert_array_equal(parents, sk.parents)
    offsets = np.array([n.translation for n in g.nodes[:sk.num_joints]])
    anim = g.animations[0]
    times = accessor(anim.samplers[0].input)[:, 0]
    np.testing.assert_allclose(times, np.arange(walk.num_frames) / walk.fps, atol=1e-6)
    assert anim.extras["fps"] == walk.fps
    rot = np.zeros((walk.num_frames, sk.num_joints, 4))
    root = None
    for ch in anim.channels:
        values = accessor(anim.samplers[ch.sampler].output)
        if ch.target.path == "translation":
            assert ch.target.node == 0
            root = values
        else:
            rot[:, ch.target.node] = values
    _, pos = fk(rot / np.linalg.norm(rot, axis=-1, keepdims=True), root, offsets, parents)
    np.testing.assert_allclose(pos, walk.positions(), atol=1e-5, rtol=0)
    # the bind pose: inverse bind matrices are the inverse of each joint's rest transform
    ibm = accessor(skin.inverseBindMatrices).reshape(-1, 4, 4).transpose(0, 2, 1)
    _, rest = fk(np.tile([0.0, 0.0, 0.0, 1.0], (sk.num_joints, 1)), offsets[0], offsets,
                 parents)
    np.testing.assert_allclose(ibm[:sk.num_joints, :3, 3], -rest, atol=1e-6)
    np.testing.assert_allclose(ibm[:, :3, :3], np.tile(np.eye(3), (len(ibm), 1, 1)))
    assert rest[:, 1].min() >= -1e-6  # the bind pose stands on the floor, Y up
    prim = g.meshes[0].primitives[0]
    joints = accessor(prim.attributes.JOINTS_0)
    weights = accessor(prim.attributes.WEIGHTS_0)
    assert set(np.unique(joints[:, 0]).astype(int)) <= set(range(sk.num_joints))
    np.testing.assert_allclose(weights[:, 0], 1.0)
    verts = accessor(prim.attributes.POSITION)
    assert verts[:, 1].max() == pytest.approx(HEIGHT, abs=1e-3)  # the head top at --height


def test_writer_refuses_other_suffixes_and_existing_files(walk, tmp_path: Path):
    with pytest.raises(InputError, match=r"\.bvh, \.glb, \.gltf"):
        write_reconstruction(walk, tmp_path / "w.fbx")
    assert not (tmp_path / "w.fbx").exists()
    write_gltf(walk, tmp_path / "w.glb", mesh=False)
    with pytest.raises(OutputExistsError):
        write_gltf(walk, tmp_path / "w.glb")


BLENDER_SCRIPT = r"""
import json, sys
import bpy
path, fps, frame = sys.argv[-3], float(sys.argv[-2]), int(sys.argv[-1])
scene = bpy.context.scene
scene.render.fps, scene.render.fps_base = round(fps), round(fps) / fps
# Shading 'FLAT': Debian 12's Blender 3.4.1 guesses it from the normals with np.bool, which
# numpy 1.24 (Debian 12's python3-numpy) no longer has; the README says so
bpy.ops.import_scene.gltf(filepath=path, import_shading="FLAT")
arm = next(o for o in scene.objects if o.type == "ARMATURE")
start, end = arm.animation_data.action.frame_range
arm.data.pose_position = "REST"
bpy.context.view_layer.update()
rest = {b.name: list(arm.matrix_world @ b.head) for b in arm.pose.bones}
arm.data.pose_position = "POSE"
scene.frame_set(int(start) + frame)
pose = {b.name: list(arm.matrix_world @ b.head) for b in arm.pose.bones}
print("RESULT " + json.dumps({"bones": len(arm.data.bones), "start": start, "end": end,
                              "rest": rest, "pose": pose,
                              "meshes": [o.name for o in scene.objects if o.type == "MESH"]}))
"""


def _blender_env() -> dict[str, str]:
    """The environment Blender runs in: a user's, without this virtual environment (whose
    packages Blender's Python would otherwise find on the PATH) when Debian's own numpy is
    there for its glTF importer."""
    env = dict(os.environ)
    venv = env.pop("VIRTUAL_ENV", None)
    plain = subprocess.run(["/usr/bin/python3", "-c", "import numpy"], check=False,
                           capture_output=True).returncode == 0
    if venv and plain:
        env["PATH"] = os.pathsep.join(p for p in env.get("PATH", "").split(os.pathsep)
                                      if not p.startswith(venv))
        env.pop("PYTHONPATH", None)
    return env


def test_blender_imports_the_glb(walk, tmp_path: Path):
    """Blender (Debian's 3.4.1, as a user runs it) imports the GLB: 21+ bones, every frame
    at the file's rate, a T-pose rest (arms level and out to the sides, legs vertical) as tall
    as --height (within 2 %), and joints where we put them (Blender is Z up: (x, -z, y))."""
    blender = shutil.which("blender")
    if blender is None:
        pytest.skip("Blender is not installed (Debian: apt-get install blender python3-numpy)")
    path = write_reconstruction(walk, tmp_path / "walk.glb", rig=None)
    script = tmp_path / "check.py"
    script.write_text(BLENDER_SCRIPT)
    run = subprocess.run([blender, "--background", "--factory-startup", "--python", str(script),
                          "--", str(path), str(walk.fps), "12"], check=False,
                         capture_output=True, text=True, timeout=300, env=_blender_env())
    if "No module named 'numpy'" in run.stdout + run.stderr:
        pytest.skip("Blender's glTF importer needs numpy (Debian: apt-get install python3-numpy)")
    line = next((ln for ln in run.stdout.splitlines() if ln.startswith("RESULT ")), None)
    assert line is not None, (run.stdout + run.stderr)[-2000:]
    res = json.loads(line[len("RESULT "):])
    assert res["bones"] >= 21 and res["meshes"]
    assert (res["start"], res["end"]) == (0, walk.num_frames - 1)
    rest = {k: np.array(v) for k, v in res["rest"].items()}
    heights = np.array([v[2] for v in rest.values()])
    assert heights.max() - heights.min() == pytest.approx(HEIGHT, rel=0.02)
    assert stature(walk.skeleton) == pytest.approx(HEIGHT)
    for side in ("Left", "Right"):
        arm, fore, hand = (rest[f"mixamorig:{side}{b}"] for b in ("Arm", "ForeArm", "Hand"))
        for joint in (fore, hand):  # level with the shoulder, out to the side
            assert abs(arm[2] - joint[2]) < 0.01 and abs(arm[1] - joint[1]) < 0.01
        assert (hand[0] - arm[0]) * (1 if side == "Left" else -1) > 0.4
        hip, knee, ankle = (rest[f"mixamorig:{side}{b}"] for b in ("UpLeg", "Leg", "Foot"))
        np.testing.assert_allclose([hip[:2], knee[:2]], [ankle[:2], ankle[:2]], atol=0.01)
    pos = walk.positions()[12]
    for k, name in enumerate(walk.skeleton.names):
        x, y, z = pos[k]
        np.testing.assert_allclose(res["pose"][name], [x, -z, y], atol=1e-4)
