"""BVH reading and writing: hand-computed forward kinematics, any channel layout and Euler order
against a plain reference reading of the format, round trips, malformed files, fuzzing."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from imuloco.core.motion import Motion
from imuloco.errors import FormatError
from imuloco.io.bvh import UNITS, read_bvh, write_bvh
from imuloco.lab.mutations import mutations
from imuloco.ops.kinematics import point_on_segment
from imuloco.ops.rotations import (
    from_6d,
    from_euler,
    from_matrix,
    from_rotvec,
    geodesic,
    normalize,
    qinv,
    qmul,
    qrot,
    to_6d,
    to_euler,
    to_matrix,
    to_rotvec,
)

ORDERS = ["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"]


# ---------------------------------------------------------------------------------------------
# A plain reference reading of BVH, independent of imuloco: per-axis matrices multiplied in
# channel order, position channels replacing the OFFSET, a loop over joints.

def _axis_matrix(axis: str, degrees: np.ndarray) -> np.ndarray:
    a = np.radians(degrees)
    c, s, o, z = np.cos(a), np.sin(a), np.ones_like(a), np.zeros_like(a)
    m = {"X": [[o, z, z], [z, c, -s], [z, s, c]],
         "Y": [[c, z, s], [z, o, z], [-s, z, c]],
         "Z": [[c, -s, z], [s, c, z], [z, z, o]]}[axis]
    return np.moveaxis(np.array(m), -1, 0)  # (T, 3, 3)


def reference_positions(text: str, scale: float) -> tuple[list[str], np.ndarray]:
    """Joint names and world positions (T, J, 3) in metres of a BVH text."""
    head, motion = text.split("MOTION")
    toks = head.split()
    names: list[str] = []
    parents: list[int] = []
    offsets: list[np.ndarray] = []
    chans: list[list[str]] = []
    stack: list[int | None] = []
    pending: int | None = None
    i = 0
    while i < len(toks):
        t = toks[i]
        if t in ("ROOT", "JOINT"):
            parents.append(next((s for s in reversed(stack) if s is not None), -1))
            names.append(toks[i + 1])
            offsets.append(np.zeros(3))
            chans.append([])
            pending = len(names) - 1
            i += 2
        elif t == "End":
            pending = None
            i += 2
        elif t == "{":
            stack.append(pending)
            i += 1
        elif t == "}":
            stack.pop()
            i += 1
        elif t == "OFFSET":
            if stack[-1] is not None:
                offsets[stack[-1]] = np.array(toks[i + 1:i + 4], dtype=float)
            i += 4
        elif t == "CHANNELS":
            n = int(toks[i + 1])
            chans[stack[-1]] = toks[i + 2:i + 2 + n]
            i += 2 + n
        else:
            i += 1
    rows = [ln.split() for ln in motion.splitlines()[3:] if ln.strip()]
    data = np.array(rows, dtype=float)
    t_count = len(data)
    world_r, world_p = [], []
    col = 0
    for j, ch in enumerate(chans):
        trans = np.tile(offsets[j], (t_count, 1))
        rot = np.tile(np.eye(3), (t_count, 1, 1))
        for c in ch:
            if c.lower().endswith("position"):
                trans[:, "XYZ".index(c[0].upper())] = data[:, col]
            else:
                rot = rot @ _axis_matrix(c[0].upper(), data[:, col])
            col += 1
        if parents[j] < 0:
            world_r.append(rot)
            world_p.append(trans)
        else:
            p = parents[j]
            world_p.append(world_p[p] + np.einsum("tij,tj->ti", world_r[p], trans))
            world_r.append(world_r[p] @ rot)
    return names, np.stack(world_p, axis=1) * scale


# ---------------------------------------------------------------------------------------------
# Generated fixtures.

TWO_JOINT = """\
HIERARCHY
ROOT root
{
\tOFFSET 0 0 0
\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
\tJOINT child
\t{
\t\tOFFSET 0 100 0
\t\tCHANNELS 3 Zrotation Xrotation Yrotation
\t\tEnd Site
\t\t{
\t\t\tOFFSET 0 50 0
\t\t}
\t}
}
MOTION
Frames: 4
Frame Time: 0.0333333
0 0 0 0 0 0 0 0 0
10 20 30 90 0 0 0 0 0
0 0 0 0 90 0 90 0 0
0 0 0 90 90 0 0 0 0
"""

# A small legged body: name, parent, offset (cm); End Sites by joint name.
BODY = [("Hips", -1, (0, 90, 0)), ("Spine", 0, (0, 12, -1)), ("Head", 1, (0, 45, 3)),
        ("LeftUpLeg", 0, (9, -5, 0)), ("LeftLeg", 3, (0, -42, 1)), ("LeftFoot", 4, (0, -40, -2)),
        ("RightUpLeg", 0, (-9, -5, 0)), ("RightLeg", 6, (0, -42, 1)),
        ("RightFoot", 7, (0, -40, -2))]
BODY_ENDS = {"Head": (0, 15, 0), "LeftFoot": (0, -5, 14), "RightFoot": (0, -5, 14)}


def bvh_text(joints, channels: list[list[str]], data: np.ndarray, fps: float = 30.0,
             ends: dict | None = None) -> str:
    """BVH text for ``joints`` (name, parent, offset) with per-joint channel lists."""
    ends = ends or {}
    out = ["HIERARCHY"]

    def emit(j: int, depth: int) -> None:
        pad = "  " * depth
        name, _, off = joints[j]
        out.append(f"{pad}{'ROOT' if depth == 0 else 'JOINT'} {name}")
        out.append(pad + "{")
        out.append(f"{pad}  OFFSET {off[0]} {off[1]} {off[2]}")
        out.append(f"{pad}  CHANNELS {len(channels[j])} {' '.join(channels[j])}")
        for k, (_, p, _) in enumerate(joints):
            if p == j:
                emit(k, depth + 1)
        if name in ends:
            e = ends[name]
            out.extend([f"{pad}  End Site", pad + "  {",
                        f"{pad}    OFFSET {e[0]} {e[1]} {e[2]}", pad + "  }"])
        out.append(pad + "}")

    emit(0, 0)
    out += ["MOTION", f"Frames: {len(data)}", f"Frame Time: {1 / fps:.7f}"]
    out += [" ".join(f"{v:.6f}" for v in row) for row in data]
    return "\n".join(out) + "\n"


def sinusoid(joints, channels: list[list[str]], frames: int = 45, seed: int = 0) -> np.ndarray:
    """Channel values: sinusoidal angles, a walking root, constant positions elsewhere."""
    rng = np.random.default_rng(seed)
    t = np.arange(frames) / 30.0
    cols = []
    for j, ch in enumerate(channels):
        for c in ch:
            if c.endswith("rotation"):
                amp, freq, phase = rng.uniform(10, 80), rng.uniform(0.5, 2), rng.uniform(0, 6.3)
                cols.append(amp * np.sin(2 * np.pi * freq * t + phase))
            elif joints[j][1] < 0:  # the root walks along +Z and bobs
                k = "XYZ".index(c[0])
                cols.append(joints[j][2][k] + [5 * np.sin(3 * t), 3 * np.cos(6 * t), 120 * t][k])
            else:
                cols.append(np.full(frames, float(joints[j][2]["XYZ".index(c[0])])))
    return np.stack(cols, axis=1)


def rot(order: str) -> list[str]:
    return [f"{a}rotation" for a in order]


POS = ["Xposition", "Yposition", "Zposition"]


def write(tmp_path: Path, name: str, text: str) -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


# ---------------------------------------------------------------------------------------------
# Forward kinematics against hand-computed positions.

def test_two_joint_fk_by_hand(tmp_path: Path):
    m = read_bvh(write(tmp_path, "two.bvh", TWO_JOINT), unit="cm")
    assert m.skeleton.names == ["root", "child"] and m.fps == 30.0 and m.num_frames == 4
    np.testing.assert_allclose(m.skeleton.offsets, [[0, 0, 0], [0, 1, 0]])
    np.testing.assert_allclose(m.skeleton.end_sites[1], [0, 0.5, 0])
    grot, pos = m.fk()
    end = point_on_segment(grot, pos, 1, m.skeleton.end_sites[1])
    # 0: rest, the child 1 m above the root and the End Site 0.5 m above that
    np.testing.assert_allclose(pos[0], [[0, 0, 0], [0, 1, 0]], atol=1e-12)
    np.testing.assert_allclose(end[0], [0, 1.5, 0], atol=1e-12)
    # 1: root at (0.1, 0.2, 0.3) m turned 90 degrees about Z: +Y becomes -X
    np.testing.assert_allclose(pos[1], [[0.1, 0.2, 0.3], [-0.9, 0.2, 0.3]], atol=1e-12)
    np.testing.assert_allclose(end[1], [-1.4, 0.2, 0.3], atol=1e-12)
    # 2: root Rx(90) takes +Y to +Z; the child's Rz(90) then turns its +Y to -X
    np.testing.assert_allclose(pos[2, 1], [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(end[2], [-0.5, 0, 1], atol=1e-12)
    # 3: channels "Zrotation Xrotation" are R = Rz Rx (intrinsic): +Y -> +Z -> +Z.
    # The extrinsic reading (Rx Rz) would put the child at -X.
    np.testing.assert_allclose(pos[3, 1], [0, 0, 1], atol=1e-12)


def test_two_joint_fixture_fk(two_joint_skeleton, spinning_motion):
    # spinning about +Y leaves a child on the axis where it is...
    np.testing.assert_allclose(spinning_motion.positions()[:, 1], np.tile([0, 1, 0], (90, 1)),
                               atol=1e-12)
    # ...and a root tilted 90 degrees about +X carries it from +Y to +Z, 1 m from the root
    q = np.zeros((2, 2, 4))
    q[..., 3] = 1
    q[1, 0] = [np.sin(np.pi / 4), 0, 0, np.cos(np.pi / 4)]
    m = Motion(two_joint_skeleton, q, [[0, 0, 0], [1, 2, 3]], 30.0)
    np.testing.assert_allclose(m.positions()[1], [[1, 2, 3], [1, 2, 4]], atol=1e-12)


# ---------------------------------------------------------------------------------------------
# Any channel layout, any Euler order, against the reference reading; then round trips.

@pytest.mark.parametrize("order", ORDERS)
def test_any_euler_order_and_round_trip(tmp_path: Path, order: str):
    channels = [POS + rot(order)] + [rot(order)] * (len(BODY) - 1)
    text = bvh_text(BODY, channels, sinusoid(BODY, channels), ends=BODY_ENDS)
    m = read_bvh(write(tmp_path, "in.bvh", text), unit="cm")
    names, ref = reference_positions(text, 0.01)
    assert m.skeleton.names == names
    np.testing.assert_allclose(m.positions(), ref, atol=1e-9)
    np.testing.assert_allclose(m.skeleton.end_sites[5], np.array(BODY_ENDS["LeftFoot"]) / 100)
    for out_order in sorted({"XYZ", "ZXY", "YZX", order}):
        for unit in ("cm", "m", "mm"):
            out = write_bvh(m, tmp_path / f"out_{out_order}_{unit}.bvh", unit=unit, order=out_order)
            back = read_bvh(out, unit=unit)
            assert back.skeleton.names == m.skeleton.names and back.fps == m.fps
            np.testing.assert_allclose(back.positions(), m.positions(), atol=1e-6, rtol=0)
            # and the written file means what it says to an independent reader
            np.testing.assert_allclose(reference_positions(out.read_text(), UNITS[unit])[1],
                                       m.positions(), atol=1e-6, rtol=0)
            assert back.skeleton.end_sites.keys() == m.skeleton.end_sites.keys()


@pytest.mark.parametrize("layout", [
    ["Yrotation", "Xposition", "Xrotation", "Zposition", "Zrotation", "Yposition"],
    ["Zrotation", "Yrotation", "Xrotation", "Xposition", "Yposition", "Zposition"],
    ["xposition", "YPOSITION", "Zposition", "Xrotation", "YRotation"],  # 2 rotations, odd case
])
def test_any_channel_layout(tmp_path: Path, layout: list[str]):
    channels = [layout, rot("YZX"), rot("XY"), ["Zrotation"], [], rot("ZXY"), rot("XZY"),
                ["Yrotation", "Xrotation"], rot("ZYX")]
    text = bvh_text(BODY, channels, sinusoid(BODY, [[c.capitalize() for c in ch]
                                                    for ch in channels]))
    m = read_bvh(write(tmp_path, "layout.bvh", text), unit="cm")
    np.testing.assert_allclose(m.positions(), reference_positions(text, 0.01)[1], atol=1e-9)
    back = read_bvh(write_bvh(m, tmp_path / "back.bvh"), unit="cm")
    np.testing.assert_allclose(back.positions(), m.positions(), atol=1e-6, rtol=0)


def test_six_channels_everywhere_and_static_root(tmp_path: Path):
    """The shared files' layout: 6 channels on every joint and a static root above the hips."""
    joints = [("joint_Root", -1, (0, 0, 0))] + [
        (n, p + 1, (0, 0, 0) if p < 0 else o) for n, p, o in BODY]
    channels = [POS + rot("ZXY")] * len(joints)
    data = sinusoid(joints, channels)
    data[:, :6] = 0.0  # joint_Root never moves
    data[:, 6:9] = np.array([3.0, 90, 1]) + np.stack(
        [np.sin(np.arange(len(data))), np.zeros(len(data)), 4.0 * np.arange(len(data))], axis=1)
    text = bvh_text(joints, channels, data, ends=BODY_ENDS)
    path = write(tmp_path, "six.bvh", text)
    names, ref = reference_positions(text, 0.01)
    m = read_bvh(path)  # auto: the legs are 82 units long, so centimetres
    assert m.skeleton.names == names[1:]  # joint_Root folded away, Hips is joint 0
    np.testing.assert_allclose(m.positions(), ref[:, 1:], atol=1e-9)
    np.testing.assert_allclose(m.skeleton.offsets[4], np.array(BODY[4][2]) / 100)
    with pytest.raises(FormatError, match="'Hips' has moving position"):
        read_bvh(path, fold_static_root=False)  # unfolded, the translating hips are no root
    # a static root that is offset and turned is folded into the hips' transform
    data[:, :6] = [20, 0, -10, 0, 0, 90]
    text = bvh_text(joints, channels, data, ends=BODY_ENDS)
    m = read_bvh(write(tmp_path, "turned.bvh", text), unit="cm")
    np.testing.assert_allclose(m.positions(), reference_positions(text, 0.01)[1][:, 1:],
                               atol=1e-9)


def test_moving_non_root_translation_is_refused(tmp_path: Path):
    channels = [POS + rot("ZXY")] * len(BODY)
    data = sinusoid(BODY, channels)
    data[:, 6 * 4 + 1] += np.linspace(0, 5, len(data))  # LeftLeg slides along Y
    path = write(tmp_path, "slide.bvh", bvh_text(BODY, channels, data))
    with pytest.raises(FormatError, match="LeftLeg.*moving position") as e:
        read_bvh(path)
    assert e.value.line == path.read_text().splitlines().index("    JOINT LeftLeg") + 1


def test_moving_root_and_moving_hips_are_folded(tmp_path: Path):
    """bandai-namco-1's `normal` layout: joint_Root walks and the Hips' position channels
    move too; both translations are applied (the Hips' world path is the root's transform
    applied to the Hips' own), not refused."""
    joints = [("joint_Root", -1, (0, 0, 0))] + [
        (n, p + 1, (0, 0, 0) if p < 0 else o) for n, p, o in BODY]
    channels = [POS + rot("ZXY")] * len(joints)
    data = sinusoid(joints, channels)
    t = np.arange(len(data))
    data[:, :6] = np.stack([np.zeros_like(t), np.zeros_like(t), 14.0 * t, 5 * np.sin(t / 7),
                            np.zeros_like(t), np.zeros_like(t)], axis=1)  # walks, turns
    data[:, 6:9] = np.array([0.2, 82.0, -5.0]) + np.stack(
        [np.sin(t / 3), 2 * np.cos(t / 2), 0.5 * t], axis=1)  # the hips move as well
    text = bvh_text(joints, channels, data, ends=BODY_ENDS)
    m = read_bvh(write(tmp_path, "normal.bvh", text), unit="cm")
    assert m.skeleton.names == [n for n, _, _ in BODY]
    np.testing.assert_allclose(m.positions(), reference_positions(text, 0.01)[1][:, 1:],
                               atol=1e-9)


def test_skip_frames(tmp_path: Path):
    channels = [POS + rot("ZXY")] + [rot("ZXY")] * (len(BODY) - 1)
    text = bvh_text(BODY, channels, sinusoid(BODY, channels))
    path = write(tmp_path, "tpose.bvh", text)
    m = read_bvh(path, skip_frames=1)
    ref = reference_positions(text, 0.01)[1]
    assert m.num_frames == len(ref) - 1
    np.testing.assert_allclose(m.positions(), ref[1:], atol=1e-9)
    with pytest.raises(FormatError, match="leaves none") as e:
        read_bvh(path, skip_frames=len(ref))
    assert e.value.path == str(path)
    with pytest.raises(ValueError, match="skip_frames"):
        read_bvh(path, skip_frames=-1)


def test_z_up_files_come_out_y_up(tmp_path: Path):
    """A Z-up file (the Y-up body turned by +90 degrees about X) is detected and turned back;
    ``up="y"`` keeps it as written; the rig's rest pose turns with it."""
    from imuloco.io.upaxis import Z_TO_Y, detect_up, to_y_up
    channels = [POS + rot("ZXY")] + [rot("ZXY")] * (len(BODY) - 1)
    text = bvh_text(BODY, channels, sinusoid(BODY, channels), ends=BODY_ENDS)
    y_up = read_bvh(write(tmp_path, "y.bvh", text), unit="cm")
    assert detect_up(y_up) == "y"
    z_up = to_y_up(y_up, "z")  # the inverse turn, applied 3 times, is Y -> Z up
    for _ in range(2):
        z_up = to_y_up(z_up, "z")
    np.testing.assert_allclose(z_up.positions()[..., 2], y_up.positions()[..., 1], atol=1e-9)
    path = write_bvh(z_up, tmp_path / "z.bvh")
    assert detect_up(read_bvh(path, up="y")) == "z"
    # the written Z-up file, read by the independent reference, turned by hand: (x, z, -y)
    ref = reference_positions(path.read_text(), 0.01)[1]
    turned = np.stack([ref[..., 0], ref[..., 2], -ref[..., 1]], axis=-1)
    for up in ("auto", "z"):
        back = read_bvh(path, up=up)
        np.testing.assert_allclose(back.positions(), y_up.positions(), atol=1e-6, rtol=0)
        np.testing.assert_allclose(back.positions(), turned, atol=1e-6, rtol=0)
        np.testing.assert_allclose(back.skeleton.offsets, y_up.skeleton.offsets, atol=1e-8)
    np.testing.assert_allclose(read_bvh(path, up="y").positions(), ref, atol=1e-6, rtol=0)
    np.testing.assert_allclose(qrot(Z_TO_Y, [0, 0, 1.0]), [0, 1, 0], atol=1e-12)
    with pytest.raises(ValueError, match="up must be"):
        read_bvh(path, up="x")


def test_root_offset_added_when_the_channels_are_relative(tmp_path: Path):
    """iClone's layout: the root's OFFSET holds the hip height and its position channels only
    the motion about it. Read as the format says the feet would be under the floor; ``auto``
    adds the OFFSET, ``replace`` does not, and an absolute file is left as it is."""
    channels = [POS + rot("ZXY")] + [rot("ZXY")] * (len(BODY) - 1)
    data = sinusoid(BODY, channels)
    data[:, 1] -= 90.0  # channels relative to the OFFSET (0, 90, 0)
    text = bvh_text(BODY, channels, data)
    path = write(tmp_path, "relative.bvh", text)
    ref = reference_positions(text, 0.01)[1]  # the format's reading
    np.testing.assert_allclose(read_bvh(path, root_offset="replace").positions(), ref,
                               atol=1e-9)
    for how in ("auto", "add"):
        np.testing.assert_allclose(read_bvh(path, root_offset=how).positions(),
                                   ref + [0, 0.9, 0], atol=1e-9)
    absolute = write(tmp_path, "absolute.bvh", bvh_text(BODY, channels, sinusoid(BODY, channels)))
    np.testing.assert_allclose(read_bvh(absolute).positions(),
                               reference_positions(absolute.read_text(), 0.01)[1], atol=1e-9)


def test_cli_reading_options(tmp_path: Path):
    import json

    from click.testing import CliRunner

    from imuloco.cli import cli
    channels = [POS + rot("ZXY")] + [rot("ZXY")] * (len(BODY) - 1)
    path = write(tmp_path, "c.bvh", bvh_text(BODY, channels, sinusoid(BODY, channels)))
    for args, frames in (([], 45), (["--skip-frames", "1", "--up", "y"], 44)):
        res = CliRunner().invoke(cli, ["info", str(path), "--json", *args])
        assert res.exit_code == 0, res.output
        assert json.loads(res.output)["frames"] == frames
    res = CliRunner().invoke(cli, ["info", str(path), "--up", "x"])
    assert res.exit_code == 2 and "--up" in res.output


@pytest.mark.parametrize("frame_time, fps", [("0.0333333", 30.0), ("0.016667", 60.0),
                                             ("0.008333", 120.0), ("0.04", 25.0),
                                             ("0.03", 100 / 3), ("0.0166666666667", 60.0)])
def test_frame_rate_from_printed_frame_time(tmp_path: Path, frame_time: str, fps: float):
    text = TWO_JOINT.replace("Frame Time: 0.0333333", f"Frame Time: {frame_time}")
    assert read_bvh(write(tmp_path, "f.bvh", text)).fps == pytest.approx(fps, rel=1e-12)


def test_names_with_spaces_crlf_and_bom(tmp_path: Path):
    text = TWO_JOINT.replace("JOINT child", "JOINT left knee {").replace(
        "\tJOINT left knee {\n\t{", "\tJOINT left knee {")
    path = tmp_path / "odd.bvh"
    path.write_bytes(b"\xef\xbb\xbf" + text.replace("\n", "\r\n").encode())
    m = read_bvh(path, unit="cm")
    assert m.skeleton.names == ["root", "left knee"]
    np.testing.assert_allclose(m.positions()[1, 1], [-0.9, 0.2, 0.3], atol=1e-12)


def test_unit_guess(tmp_path: Path):
    """Metres, centimetres, millimetres and the CMU unit (CMU BVH conversions) by leg length."""
    cmu = [("Hips", -1, (0, 0, 0)), ("LHipJoint", 0, (0, 0, 0)),
           ("LeftUpLeg", 1, (1.65, -1.8, 0.85)), ("LeftLeg", 2, (2.5, -6.8, 0)),
           ("LeftFoot", 3, (2.6, -7.1, 0))]
    channels = [POS + rot("ZYX")] + [rot("ZYX")] * 4
    data = sinusoid(cmu, channels, frames=3)
    m = read_bvh(write(tmp_path, "cmu.bvh", bvh_text(cmu, channels, data)))
    femur = np.linalg.norm([2.5, -6.8, 0]) * 0.0254 / 0.45
    assert abs(np.linalg.norm(m.skeleton.offsets[3]) - femur) < 1e-12
    assert 0.3 < femur < 0.5  # a human thigh
    for unit, k in (("m", 0.01), ("cm", 1.0), ("mm", 10.0)):
        body = [(n, p, tuple(k * v for v in o)) for n, p, o in BODY]
        ch = [POS + rot("ZXY")] + [rot("ZXY")] * (len(BODY) - 1)
        m = read_bvh(write(tmp_path, f"{unit}.bvh", bvh_text(body, ch, sinusoid(body, ch))))
        np.testing.assert_allclose(m.skeleton.offsets[4], np.array(BODY[4][2]) / 100)
    # a toy skeleton without legs falls back to bone lengths: 100 units means centimetres
    assert read_bvh(write(tmp_path, "toy.bvh", TWO_JOINT)).skeleton.offsets[1, 1] == 1.0
    with pytest.raises(ValueError, match="unit"):
        read_bvh(tmp_path / "toy.bvh", unit="furlong")


def test_write_refuses_to_overwrite(tmp_path: Path):
    m = read_bvh(write(tmp_path, "two.bvh", TWO_JOINT), unit="cm")
    out = write_bvh(m, tmp_path / "out.bvh")
    before = out.read_text()
    with pytest.raises(FileExistsError, match="exists"):
        write_bvh(m.slice(0, 2), out)
    assert out.read_text() == before
    write_bvh(m.slice(0, 2), out, overwrite=True)
    assert read_bvh(out, unit="cm").num_frames == 2
    with pytest.raises(FileExistsError):
        write_bvh(m, tmp_path / "two.bvh")  # the input is protected too
    with pytest.raises(ValueError, match="permutation"):
        write_bvh(m, tmp_path / "bad.bvh", order="XXY")
    assert not (tmp_path / "bad.bvh").exists()


# ---------------------------------------------------------------------------------------------
# Malformed files: one error type naming the file, the line and what was expected.

def _edit(line: int, new: str | None):
    def f(text: str) -> str:
        lines = text.splitlines()
        if new is None:
            del lines[line - 1]
        else:
            lines[line - 1] = new
        return "\n".join(lines) + "\n"
    return f


MALFORMED = {
    "truncated MOTION block": (_edit(22, None), 21, "truncated MOTION block"),
    "truncated mid-frame": (lambda t: t[: t.rindex("90 0 0 0 0")], 22, "expected 9 channel"),
    "wrong channel count": (_edit(20, "10 20 30 90 0 0 0 0"), 20, "expected 9 channel values"),
    "too many values": (_edit(20, "10 20 30 90 0 0 0 0 0 0"), 20, "found 10"),
    "non-numeric value": (_edit(21, "0 0 0 0 abc 0 90 0 0"), 21, "'abc'"),
    "unknown channel": (_edit(9, "CHANNELS 3 Zrotation Wrotation Yrotation"), 9,
                        "unknown channel 'Wrotation'"),
    "NaN value": (_edit(20, "10 20 nan 90 0 0 0 0 0"), 20, "root Zposition"),
    "infinite value": (_edit(20, "10 20 30 90 0 0 0 -inf 0"), 20, "child Xrotation"),
    "absurd value": (_edit(20, "10 20 30 90 0 0 0 1e300 0"), 20, "below"),
    "NaN offset": (_edit(8, "OFFSET 0 nan 0"), 8, "finite"),
    "extra frame": (lambda t: t + "0 0 0 0 0 0 0 0 0\n", 23, "goes on"),
    "bad frame count": (_edit(17, "Frames: four"), 17, "frame count"),
    "missing frame count": (_edit(17, None), 17, "Frames"),
    "zero frame time": (_edit(18, "Frame Time: 0"), 18, "Frame Time"),
    "nan frame time": (_edit(18, "Frame Time: nan"), 18, "Frame Time"),
    "frame time of 1000 s": (_edit(18, "Frame Time: 1000"), 18, "1 to 1000 fps"),
    "frame rate of 1e6": (_edit(18, "Frame Time: 1e-6"), 18, "1 to 1000 fps"),
    "no MOTION": (lambda t: t.replace("MOTION", "MOTON"), 16, "MOTION"),
    "missing brace": (_edit(15, None), 14, "ends early"),
    "extra brace": (_edit(15, "}\n}"), 16, "expected MOTION after the ROOT joint, found '}'"),
    "glued brace": (_edit(15, "}}"), 15, "found '}}'"),
    "bad channel count": (_edit(9, "CHANNELS three Zrotation Xrotation Yrotation"), 9,
                          "channel count"),
    "repeated channel": (_edit(9, "CHANNELS 3 Zrotation Xrotation Zrotation"), 9, "repeats"),
    "duplicate joint": (_edit(6, "JOINT root"), 6, "used twice"),
    "missing OFFSET": (_edit(8, None), 6, "OFFSET"),
    "garbage keyword": (_edit(10, "Endsite"), 10, "End Site"),
    "no HIERARCHY": (_edit(1, "HIERARCY"), 1, "HIERARCHY"),
    "no channels": (lambda t: t.replace("CHANNELS 6 Xposition Yposition Zposition Zrotation "
                                        "Xrotation Yrotation", "CHANNELS 0").replace(
        "CHANNELS 3 Zrotation Xrotation Yrotation", "CHANNELS 0"), 16, "channels"),
}


@pytest.mark.parametrize("case", list(MALFORMED))
def test_malformed(tmp_path: Path, case: str):
    mutate, line, words = MALFORMED[case]
    path = write(tmp_path, "bad.bvh", mutate(TWO_JOINT))
    with pytest.raises(FormatError) as e:
        read_bvh(path)
    assert e.value.path == str(path)
    assert str(e.value).startswith(f"{path}:{line}: "), str(e.value)
    assert words in e.value.message, e.value.message


def test_not_text(tmp_path: Path):
    path = tmp_path / "binary.bvh"
    path.write_bytes(bytes(range(256)))
    with pytest.raises(FormatError, match="HIERARCHY"):
        read_bvh(path)


# ---------------------------------------------------------------------------------------------
# Property tests: rotation round trips and a parser that fails only with FormatError.

quaternions = st.lists(st.floats(-1, 1), min_size=4, max_size=4).map(np.array).filter(
    lambda q: np.linalg.norm(q) > 0.1).map(normalize)
angles = st.lists(st.floats(-180, 180), min_size=3, max_size=3).map(np.array)
# scipy's Euler extraction snaps to the gimbal-lock solution within ~1e-7 of it, which costs up
# to 2e-7 rad (measured); everything else round-trips to machine precision.
EULER_TOL = 1e-6
SETTINGS = settings(derandomize=True, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@SETTINGS
@given(q=quaternions, order=st.sampled_from(ORDERS))
def test_euler_round_trip(q: np.ndarray, order: str):
    assert geodesic(q, from_euler(to_euler(q, order), order)) < EULER_TOL


@SETTINGS
@given(a=angles, order=st.sampled_from(ORDERS))
def test_euler_angles_round_trip(a: np.ndarray, order: str):
    q = from_euler(a, order)
    assert geodesic(q, from_euler(to_euler(q, order), order)) < EULER_TOL
    # an intrinsic order is the product of its axis rotations, first axis outermost
    axes = {"X": np.eye(3)[0], "Y": np.eye(3)[1], "Z": np.eye(3)[2]}
    parts = [from_rotvec(axes[ax] * np.radians(v)) for ax, v in zip(order, a)]
    assert geodesic(q, qmul(qmul(parts[0], parts[1]), parts[2])) < 1e-9


@SETTINGS
@given(q=quaternions, r=quaternions, v=st.lists(st.floats(-10, 10), min_size=3, max_size=3))
def test_rotation_representations(q: np.ndarray, r: np.ndarray, v: list[float]):
    assert geodesic(q, from_matrix(to_matrix(q))) < 1e-9
    assert geodesic(q, from_rotvec(to_rotvec(q))) < 1e-9
    assert geodesic(q, from_6d(to_6d(q))) < 1e-9
    assert geodesic(qmul(q, qinv(q)), np.array([0, 0, 0, 1.0])) < 1e-9
    np.testing.assert_allclose(qrot(qmul(q, r), v), qrot(q, qrot(r, v)), atol=1e-9)
    np.testing.assert_allclose(qrot(q, v), to_matrix(q) @ np.array(v), atol=1e-9)


@SETTINGS
@given(d=st.lists(st.floats(-10, 10), min_size=6, max_size=6))
def test_from_6d_of_any_pair_is_its_gram_schmidt_rotation(d: list[float]):
    """A network's raw 6-D output (not unit, not orthogonal) gives the rotation whose first
    column is its first vector and whose second lies in the pair's plane, as SciPy's
    orthogonalizing conversion of the Gram-Schmidt matrix does (the fast path skips it)."""
    a, b = np.array(d[:3]), np.array(d[3:])
    assume(np.linalg.norm(a) > 0.1 and np.linalg.norm(np.cross(a, b)) > 0.1 * np.linalg.norm(a))
    q = from_6d(np.array(d))
    m = to_matrix(q)
    np.testing.assert_allclose(m[:, 0], a / np.linalg.norm(a), atol=1e-9)
    assert np.dot(m[:, 1], b) > 0 and abs(np.dot(m[:, 2], b)) < 1e-9
    c = a / np.linalg.norm(a)
    g = b - np.dot(c, b) * c
    g /= np.linalg.norm(g)
    assert geodesic(q, from_matrix(np.stack([c, g, np.cross(c, g)], axis=-1))) < 1e-9


@settings(SETTINGS, max_examples=25)
@given(order=st.sampled_from(ORDERS), q=st.lists(quaternions, min_size=6, max_size=6),
       root=st.lists(st.floats(-1e3, 1e3), min_size=3, max_size=3))
def test_write_read_round_trip_property(tmp_path_factory, order: str, q, root):
    """Any rotations, written in any Euler order, come back to 1e-6 m (even at gimbal lock:
    3 joints x 2e-7 rad x under 1 m of lever, plus 1e-8 m of rounding)."""
    from imuloco.core.skeleton import Skeleton
    sk = Skeleton(["a", "b", "c"], np.array([-1, 0, 1]), [[0, 0, 0], [0, 0.5, 0], [0.3, 0, 0.2]])
    m = Motion(sk, np.array(q).reshape(2, 3, 4), np.array([root, root]), 30.0)
    path = write_bvh(m, tmp_path_factory.mktemp("rt") / "m.bvh", unit="cm", order=order)
    back = read_bvh(path, unit="cm")
    np.testing.assert_allclose(back.positions(), m.positions(), atol=1e-6, rtol=0)


TOKENS = ["{", "}", "JOINT", "ROOT", "End", "Site", "OFFSET", "CHANNELS", "3", "6", "0", "-1",
          "Xrotation", "Yposition", "nan", "inf", "1e999", "1e308", "1e-320", "MOTION", "Frames:",
          "Frame Time:", "\n", " ", "\t", "x", "²", "٣", "-0", "1e9", "#"]


@st.composite
def mangled(draw) -> str:
    text = TWO_JOINT
    for _ in range(draw(st.integers(1, 4))):
        i = draw(st.integers(0, len(text)))
        j = draw(st.integers(i, min(len(text), i + 30)))
        kind = draw(st.sampled_from(["delete", "insert", "replace", "truncate", "duplicate"]))
        piece = draw(st.one_of(st.sampled_from(TOKENS), st.text(max_size=6)))
        if kind == "delete":
            text = text[:i] + text[j:]
        elif kind == "insert":
            text = text[:i] + piece + text[i:]
        elif kind == "replace":
            text = text[:i] + piece + text[j:]
        elif kind == "truncate":
            text = text[:i]
        else:
            text = text[:j] + text[i:j] + text[j:]
    return text


@settings(SETTINGS, max_examples=300)
@given(text=st.one_of(mangled(), st.text(max_size=200)))
def test_parser_fails_only_with_format_error(tmp_path_factory, text: str):
    path = tmp_path_factory.getbasetemp() / "fuzz.bvh"
    path.write_text(text, encoding="utf-8", errors="surrogatepass")
    try:
        m = read_bvh(path)
    except FormatError as e:
        assert e.path == str(path) and e.message
        return
    assert np.all(np.isfinite(m.positions())) and m.fps > 0


def read_or_format_error(path: Path) -> Motion | None:
    """The reader's contract: a valid Motion, or a FormatError naming this file and a line of
    it (or none); nothing else."""
    try:
        m = read_bvh(path)
    except FormatError as e:
        assert e.path == str(path) and e.message
        lines = path.read_bytes().count(b"\n") + 2
        assert e.line is None or 1 <= e.line <= lines, (e.line, lines)
        return None
    assert m.num_frames >= 1 and 1 <= m.fps <= 1000
    assert np.all(np.isfinite(m.positions()))
    return m


@settings(SETTINGS, max_examples=300)
@given(data=mutations(TWO_JOINT))
def test_byte_mutations_fail_only_with_format_error(tmp_path_factory, data: bytes):
    path = tmp_path_factory.getbasetemp() / "bytes.bvh"
    path.write_bytes(data)
    read_or_format_error(path)


NUMBERS = st.one_of(st.floats().map(repr), st.integers().map(str), st.text(max_size=12),
                    st.sampled_from(["1e-6", "1000", "0", "-1", "9" * 5000, "1_0", "0x10",
                                     "\u0663", "nan", "1e308", "5e-324"]))


@settings(SETTINGS, max_examples=200)
@given(frames=NUMBERS, frame_time=NUMBERS, value=NUMBERS, cut=st.integers(0, len(TWO_JOINT)))
def test_malformed_headers_numbers_and_truncation(tmp_path_factory, frames: str,
                                                  frame_time: str, value: str, cut: int):
    d = tmp_path_factory.getbasetemp()
    texts = [TWO_JOINT.replace("Frames: 4", f"Frames: {frames}"),
             TWO_JOINT.replace("Frame Time: 0.0333333", f"Frame Time: {frame_time}"),
             TWO_JOINT.replace("10 20 30 90", f"10 {value} 30 90"),
             TWO_JOINT.replace("OFFSET 0 100 0", f"OFFSET 0 {value} 0"),
             TWO_JOINT[:cut]]
    for i, text in enumerate(texts):
        path = d / f"field{i}.bvh"
        path.write_text(text, encoding="utf-8", errors="surrogatepass")
        m = read_or_format_error(path)
        if i == 4 and m is not None:  # only the whole file, or it without its last newline
            assert cut >= len(TWO_JOINT) - 1


@settings(SETTINGS, max_examples=60)
@given(values=st.lists(st.floats(-1e9, 1e9), min_size=18, max_size=18),
       fmt=st.sampled_from(["{:.6f}", "{!r}", "{:.3e}", "{:g}", "{:+.2f}"]),
       sep=st.sampled_from([" ", "\t", "  ", " \t "]), crlf=st.booleans())
def test_fast_and_line_by_line_readings_agree(values, fmt: str, sep: str, crlf: bool):
    """The one-pass MOTION reading gives the reference line-by-line reading's numbers."""
    from imuloco.io import bvh as reader
    head, _ = TWO_JOINT.split("MOTION")
    rows = [sep.join(fmt.format(v) for v in values[:9]), sep.join(fmt.format(v)
                                                                 for v in values[9:])]
    text = head + "MOTION\nFrames: 2\nFrame Time: 0.01\n" + "\n".join(rows) + "\n"
    text = text.replace("\n", "\r\n") if crlf else text
    path = Path("fast.bvh")
    joints, fps, fast = reader.parse_bvh(path, text)
    lines = text.splitlines()
    at = lines.index("MOTION") + 1
    slow_fps, slow = reader._parse_motion(path, iter(list(enumerate(lines, 1))[at:]), at,
                                          joints)
    assert fps == slow_fps == 100.0
    np.testing.assert_array_equal(fast, slow)


def test_limits(tmp_path: Path):
    """Frame rates, counts, joint numbers and depth have plausible ranges; 20,000 joints are
    refused at once (the name check is linear)."""
    chain = "".join(f"JOINT j{i}\n{{\nOFFSET 0 1 0\nCHANNELS 3 Xrotation Yrotation "
                    "Zrotation\n" for i in range(20_000))
    deep = ("HIERARCHY\nROOT r\n{\nOFFSET 0 0 0\nCHANNELS 3 Xrotation Yrotation Zrotation\n"
            + chain + "}\n" * 20_001 + "MOTION\nFrames: 1\nFrame Time: 0.03\n0\n")
    wide = deep.replace(chain, chain.replace("JOINT", "}\nJOINT")[2:]).replace(
        "}\n" * 20_001, "}\n}\n")
    for name, text, words in [("deep", deep, "nested more than 256"),
                              ("wide", wide, "more than 2000 joints"),
                              ("digits", TWO_JOINT.replace("Frames: 4", "Frames: " + "9" * 5000),
                               "frame count from 1 to"),
                              ("channels", TWO_JOINT.replace("CHANNELS 3", "CHANNELS 7"),
                               "channel count from 0 to 6")]:
        with pytest.raises(FormatError, match=words):
            read_bvh(write(tmp_path, f"{name}.bvh", text))


# ---------------------------------------------------------------------------------------------
# Real data.

def test_bundled_sample_against_reference():
    from imuloco.data import SAMPLE_DIR
    path = SAMPLE_DIR / "dataset-2_walk_normal_001.bvh"
    m = read_bvh(path)
    names, ref = reference_positions(path.read_text(), 0.01)
    assert names[0] == "joint_Root" and m.skeleton.names == names[1:]
    assert m.num_frames == 273 and m.fps == 30.0
    np.testing.assert_allclose(m.positions(), ref[:, 1:], atol=1e-9)
    assert set(m.skeleton.body_map) >= {"pelvis", "left_ankle", "right_wrist"}


@pytest.mark.shared
def test_shared_clip_round_trip(shared_dir: Path, tmp_path: Path):
    path = shared_dir / "dataset-2_run_normal_001.bvh"
    m = read_bvh(path)
    assert m.skeleton.num_joints == 21 and m.fps == 30.0
    np.testing.assert_allclose(m.positions(), reference_positions(path.read_text(), 0.01)[1][:, 1:],
                               atol=1e-9)
    back = read_bvh(write_bvh(m, tmp_path / "copy.bvh"))
    assert back.skeleton.names == m.skeleton.names and back.num_frames == m.num_frames
    err = np.abs(back.positions() - m.positions()).max()
    assert err < 1e-6, err


@pytest.mark.shared
@pytest.mark.parametrize("folder, joints, fps", [("bandai-namco-1", {21}, 30.0),
                                                 ("cmu-iclone", {100, 101}, 60.0)])
def test_every_shared_clip_loads(shared_dir: Path, folder: str, joints: set, fps: float):
    """Every clip of the other shared folders loads, Y up, feet near the floor:
    bandai-namco-1 (the `normal` style's moving Hips) and cmu-iclone (Character Creator rig,
    T-pose frame 0 skipped). cmu-iclone holds two rigs: 4 clips under an `RL_BoneRoot` (101
    joints, the rig Z up at rest, turned Y up by the root in every frame) and 26 rooted at
    `CC_Base_Hip` (100 joints) whose root position channels are meant to be added to its
    OFFSET (read as the format says, the feet would be 0.96 m under the floor)."""
    files = sorted((shared_dir.parent / folder).glob("*.bvh"))
    assert len(files) >= 30
    for f in files:
        m = read_bvh(f, skip_frames=1)
        assert m.skeleton.num_joints in joints and m.fps == fps, f
        p = m.positions()
        height = np.ptp(p, axis=1).max(axis=0)
        assert 1.0 < height[1] < 2.2, (f, height)  # a person, in metres, standing along Y
        lowest = np.median(p[..., 1].min(axis=1))
        assert -0.01 < lowest < 0.5, (f, lowest)  # on the floor (or on uneven terrain)


def test_limited_database_spreads_over_the_folder(sample_db):
    from imuloco.data import SAMPLE_DIR
    from imuloco.io.database import load_database, spread

    assert spread(10, 3) == [0, 4, 9] and spread(4, None) == [0, 1, 2, 3]
    db = load_database(SAMPLE_DIR, limit=4, progress=False)
    assert len(db) == 4
    assert len({lab["content"] for lab in db.labels}) >= 3  # not only the first type by name


def test_joint_positions_match_fk(sample_db):
    from imuloco.ops.kinematics import joint_positions
    m = sample_db.clips[0]
    sk = m.skeleton
    picks = [sk.part(p) for p in ("head", "left_ankle", "right_wrist")] + [0]
    for frames in (slice(0, 4), slice(None)):  # a few rotations, and many (scipy's conversion)
        np.testing.assert_allclose(
            joint_positions(m.rotations[frames], m.root[frames], sk.offsets, sk.parents, picks),
            m.positions()[frames, picks], atol=1e-12)
    everyone = list(range(sk.num_joints))
    assert m.num_frames * sk.num_joints > 1024
    np.testing.assert_allclose(
        joint_positions(m.rotations, m.root, sk.offsets, sk.parents, everyone), m.positions(),
        atol=1e-12)


# ---------------------------------------------------------------------------------------------
# The writer, checked by an independent reader (bvhio) and, where it is installed, Blender.

@pytest.mark.parametrize("unit, per_metre", [("cm", 100.0), ("m", 1.0)])
def test_written_units_and_end_sites_in_bvhio(sample_db, tmp_path: Path, unit: str,
                                              per_metre: float):
    """bvhio reads our file to our world positions in the chosen unit; every leaf has a
    non-zero End Site though the rig's are of zero length (head top ~21 cm, hands, toes)."""
    bvhio = pytest.importorskip("bvhio")
    m = sample_db.clips[0].slice(0, 30)
    assert all(np.linalg.norm(v) == 0 for v in m.skeleton.end_sites.values())
    path = write_bvh(m, tmp_path / f"w_{unit}.bvh", unit=unit)
    root = bvhio.readAsHierarchy(str(path))
    pos = m.positions()
    for f in (0, 29):
        root.loadPose(f)
        got = {j.Name: np.array(j.PositionWorld) / per_metre for j, *_ in root.layout()}
        for k, name in enumerate(m.skeleton.names):
            np.testing.assert_allclose(got[name], pos[f, k], atol=1e-5)
    ends = {j.Name: np.linalg.norm(j.EndSite) / per_metre
            for j, *_ in bvhio.readAsBvh(str(path)).Root.layout() if not j.Children}
    assert set(ends) == {"Head", "Hand_L", "Hand_R", "Toes_L", "Toes_R"}
    assert 0.15 < ends["Head"] < 0.3 and 0.1 < ends["Hand_L"] < 0.25, ends
    assert 0.02 < ends["Toes_R"] < 0.1, ends
    back = read_bvh(path, unit=unit)
    np.testing.assert_allclose(back.positions(), pos, atol=1e-6, rtol=0)


def test_end_site_of_a_rig_without_body_map():
    from imuloco.core.skeleton import Skeleton
    from imuloco.io.bvh import end_site
    sk = Skeleton(["a", "b"], np.array([-1, 0]), [[0, 0, 0], [0, 0, 0.3]], {1: np.zeros(3)})
    np.testing.assert_allclose(end_site(sk, 1), [0, 0, 0.15])  # half its bone
    sk = Skeleton(["a", "b"], np.array([-1, 0]), [[0, 0, 0], [0, 0, 0.3]], {1: [1.0, 0, 0]})
    np.testing.assert_allclose(end_site(sk, 1), [1, 0, 0])  # the rig's own is kept


BLENDER_SCRIPT = r"""
import builtins, json, sys
import bpy
_open = builtins.open
def _open_without_U(file, mode="r", *args, **kwargs):
    # Debian's Blender 3.4 BVH importer opens with mode 'rU', which Python 3.11 refuses;
    # patched here, in the test only.
    return _open(file, mode.replace("U", "") if isinstance(mode, str) else mode, *args, **kwargs)
builtins.open = _open_without_U
path, scale, frame = sys.argv[-3], float(sys.argv[-2]), int(sys.argv[-1])
bpy.ops.import_anim.bvh(filepath=path, global_scale=scale, update_scene_fps=True,
                        update_scene_duration=True)
arm = next(o for o in bpy.context.scene.objects if o.type == "ARMATURE")
scene = bpy.context.scene
scene.frame_set(scene.frame_start + frame)
bones = {b.name: [list(arm.matrix_world @ b.head), list(arm.matrix_world @ b.tail)]
         for b in arm.pose.bones}
print("RESULT " + json.dumps({"fps": scene.render.fps / scene.render.fps_base,
                              "frame_end": scene.frame_end, "bones": bones}))
"""


@pytest.mark.parametrize("unit, scale", [("cm", 0.01), ("m", 1.0)])
def test_blender_imports_the_written_bvh(sample_db, tmp_path: Path, unit: str, scale: float):
    """Blender (Debian's, run in the background) imports the file as the README says: scale
    0.01 for centimetres, 1 for metres, the scene at the file's frame rate; joints where we
    put them (Blender is Z up: our (x, y, z) is its (x, -z, y)) and a head bone of non-zero
    length (its tail is the End Site)."""
    import json
    import shutil
    import subprocess
    blender = shutil.which("blender")
    if blender is None:
        pytest.skip("Blender is not installed (Debian: apt-get install blender)")
    probe = subprocess.run([blender, "--background", "--factory-startup", "--python-expr",
                            "print('BLENDER-OK')"], check=False, capture_output=True, text=True,
                           timeout=300)
    if "BLENDER-OK" not in probe.stdout:
        pytest.skip(f"Blender cannot run here: {(probe.stderr or probe.stdout)[-300:]}")
    m = sample_db.clips[0].slice(0, 30)
    path = write_bvh(m, tmp_path / f"b_{unit}.bvh", unit=unit)
    script = tmp_path / "check.py"
    script.write_text(BLENDER_SCRIPT)
    run = subprocess.run([blender, "--background", "--factory-startup", "--python",
                          str(script), "--", str(path), str(scale), "12"],
                         check=False, capture_output=True, text=True, timeout=300)
    line = next((ln for ln in run.stdout.splitlines() if ln.startswith("RESULT ")), None)
    assert line is not None, (run.stdout + run.stderr)[-2000:]
    res = json.loads(line[len("RESULT "):])
    assert res["fps"] == pytest.approx(m.fps) and res["frame_end"] >= 30
    pos = m.positions()[12]
    for k, name in enumerate(m.skeleton.names):
        x, y, z = pos[k]
        np.testing.assert_allclose(res["bones"][name][0], [x, -z, y], atol=1e-4)
    head, tail = np.array(res["bones"]["Head"])
    assert 0.15 < np.linalg.norm(tail - head) < 0.3


@st.composite
def random_trees(draw) -> tuple[list[int], np.ndarray]:
    """A valid joint order that is not depth-first in general (as SMPL's is not): each joint's
    parent any earlier joint; offsets (J, 3) in metres."""
    n = draw(st.integers(2, 9))
    parents = [-1] + [draw(st.integers(0, j - 1)) for j in range(1, n)]
    offsets = np.array(draw(st.lists(st.lists(st.floats(-0.5, 0.5), min_size=3, max_size=3),
                                     min_size=n, max_size=n)))
    return parents, offsets


@settings(SETTINGS, max_examples=40)
@given(tree=random_trees(), seed=st.integers(0, 2**31 - 1), order=st.sampled_from(ORDERS))
def test_any_valid_joint_order_round_trips(tmp_path_factory, tree, seed: int, order: str):
    """A skeleton whose joints are in any valid order (parents first, not depth-first) is
    written in depth-first order with each joint's own rotation: every joint's world position
    comes back (a later branch carried other joints' rotations: 0.74 m off on SMPL's order)."""
    from imuloco.core.skeleton import Skeleton

    parents, offsets = tree
    names = [f"j{k}" for k in range(len(parents))]
    offsets[0] = 0.0
    rng = np.random.default_rng(seed)
    rotations = normalize(rng.normal(size=(3, len(names), 4)))
    m = Motion(Skeleton(names, np.array(parents), offsets), rotations,
               rng.uniform(-1, 1, size=(3, 3)), 30.0)
    path = write_bvh(m, tmp_path_factory.mktemp("order") / "m.bvh", unit="cm", order=order)
    back = read_bvh(path, unit="cm", up="y", fold_static_root=False, root_offset="replace")
    at = [back.skeleton.names.index(n) for n in names]
    np.testing.assert_allclose(back.positions()[:, at], m.positions(), atol=1e-6, rtol=0)


def _peak_bytes(read) -> int:
    """Peak bytes Python and numpy allocated while ``read()`` ran (tracemalloc)."""
    import tracemalloc

    tracemalloc.start()
    try:
        read()
    except FormatError:
        pass
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak


@pytest.mark.parametrize("where", ["offset", "name", "motion"])
def test_a_huge_line_is_refused_within_a_few_times_the_file(tmp_path: Path, where: str):
    """An 80 MB header line of '0 ' tokens took 3.4 GB (a list of its tokens); a line is read
    token by token, and a MOTION line longer than its channels can be is refused unsplit."""
    zeros = "0 " * 200_000
    text = {"offset": TWO_JOINT.replace("OFFSET 0 0 0", f"OFFSET {zeros}", 1),
            "name": TWO_JOINT.replace("JOINT child", f"JOINT {zeros}"),
            "motion": TWO_JOINT.replace("0 0 0 0 0 0 0 0 0", zeros, 1)}[where]
    path = tmp_path / "huge.bvh"
    path.write_text(text)
    with pytest.raises(FormatError, match=r"huge\.bvh:\d+: "):
        read_bvh(path)
    assert _peak_bytes(lambda: read_bvh(path)) < 12 * len(text)


def test_frames_times_joints_are_bounded(tmp_path: Path, monkeypatch):
    from imuloco.io import bvh

    path = tmp_path / "m.bvh"
    path.write_text(TWO_JOINT)
    assert read_bvh(path).num_frames == 4
    monkeypatch.setattr(bvh, "MAX_JOINT_FRAMES", 7)
    for text in (TWO_JOINT, TWO_JOINT.replace("\n", "\r")):  # the fast and the line reading
        path.write_text(text)
        with pytest.raises(FormatError, match=r"m\.bvh:17: 4 frames of 2 joints, more than the "
                                              r"7 frames x joints"):
            read_bvh(path)
