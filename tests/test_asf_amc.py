"""ASF/AMC reading: hand-computed positions on a tiny CMU-style leg, the CMU body map, errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from imuloco.core.bodymap import PARTS, resolve_body_map
from imuloco.errors import FormatError
from imuloco.io.asf_amc import find_asf, read_asf, read_asf_amc
from imuloco.io.motionfile import read_motion
from imuloco.lab.mutations import mutations

U = 0.0254 / 0.45  # metres per CMU length unit

LEG_ASF = """\
# a root and a three-bone leg, CMU conventions
:version 1.10
:name test
:units
  mass 1.0
  length 0.45
  angle deg
:documentation
  hand-written for the tests
:root
  order TX TY TZ RX RY RZ
  axis XYZ
  position 0 0 0
  orientation 0 0 0
:bonedata
  begin
    id 1
    name lfemur
    direction 0 -1 0
    length 9
    axis 0 0 0 XYZ
    dof rx ry rz
    limits (-160.0 20.0)
           (-70.0 70.0)
           (-60.0 70.0)
  end
  begin
    id 2
    name ltibia
    direction 0 -1 0
    length 9
    axis 0 0 0 XYZ
    dof rx
    limits (-10.0 170.0)
  end
  begin
    id 3
    name lfoot
    direction 0 0 1
    length 4.5
    axis 0 0 90 XYZ
    dof rx rz
    limits (-inf inf) (-inf inf)
  end
:hierarchy
  begin
    root lfemur
    lfemur ltibia
    ltibia lfoot
  end
"""

# Five frames, each testing one convention (see test_leg_positions).
LEG_AMC = """\
#!OML:ASF test.asf
:FULLY-SPECIFIED
:DEGREES
1
root 0 18 0 0 0 0
lfemur 0 0 0
ltibia 0
lfoot 0 0
2
root 0 18 0 0 0 0
lfemur 0 0 0
ltibia 90
lfoot 0 0
3
root 0 18 0 0 0 0
lfemur 0 0 0
ltibia 0
lfoot 90 0
4
root 9 18 -4.5 0 90 0
lfemur 0 0 0
ltibia 0
lfoot 0 0
5
root 0 18 0 0 0 0
lfemur 90 90 0
ltibia 0
lfoot 0 0
"""


def write(tmp_path: Path, name: str, text: str) -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


@pytest.fixture
def leg(tmp_path: Path) -> tuple[Path, Path]:
    return write(tmp_path, "leg.asf", LEG_ASF), write(tmp_path, "leg.amc", LEG_AMC)


def test_leg_skeleton(leg):
    sk = read_asf(leg[0])
    assert sk.names == ["root", "lfemur", "ltibia", "lfoot"]
    assert list(sk.parents) == [-1, 0, 1, 2]
    # joint at the bone's start: lfemur sits on the root, ltibia one femur below it
    np.testing.assert_allclose(sk.offsets, [[0, 0, 0], [0, 0, 0], [0, -9 * U, 0], [0, -9 * U, 0]])
    np.testing.assert_allclose(sk.end_sites[3], [0, 0, 4.5 * U])
    assert abs(9 * U - 0.508) < 1e-12  # 9 units = 20 inches


def test_leg_positions(leg):
    m = read_asf_amc(*leg)
    assert m.num_frames == 5 and m.fps == 120.0 and m.name == "leg"
    grot, pos = m.fk()
    h = 18 * U  # root height, 1.016 m
    f, s = 9 * U, 4.5 * U  # femur = tibia = 0.508 m, foot 0.254 m

    def toe(frame: int) -> np.ndarray:  # the End Site of lfoot
        from imuloco.ops.kinematics import point_on_segment
        return point_on_segment(grot[frame], pos[frame], 3, m.skeleton.end_sites[3])

    # 1: rest pose, a straight leg hanging from the root, foot pointing +Z
    np.testing.assert_allclose(pos[0], [[0, h, 0], [0, h, 0], [0, h - f, 0], [0, h - 2 * f, 0]],
                               atol=1e-12)
    np.testing.assert_allclose(toe(0), [0, h - 2 * f, s], atol=1e-12)
    # 2: knee rx = 90 degrees swings the shank from -Y to -Z (Rx(90) y -> z), the foot with it
    np.testing.assert_allclose(pos[1, 3], [0, h - f, -f], atol=1e-12)
    np.testing.assert_allclose(toe(1), [0, h - f - s, -f], atol=1e-12)
    # 3: foot rx = 90 about its axis frame C = Rz(90): C Rx(90) C^-1 is Ry(90), +Z -> +X
    np.testing.assert_allclose(toe(2), [s, h - 2 * f, 0], atol=1e-12)
    # 4: root translation (9, 18, -4.5) and yaw 90 degrees: the leg hangs, the foot turns to +X
    np.testing.assert_allclose(pos[3, 0], [9 * U, h, -4.5 * U], atol=1e-12)
    np.testing.assert_allclose(toe(3), [9 * U + s, h - 2 * f, -4.5 * U], atol=1e-12)
    # 5: femur dof rx ry rz = 90 90 0 is R = Ry(90) Rx(90) (fixed axes, x first):
    # -Y -> (Rx) -Z -> (Ry) -X. The other convention (Rx Ry) would give -Z.
    np.testing.assert_allclose(pos[4, 2], [-f, h, 0], atol=1e-12)


def test_fps_units_and_radians(tmp_path: Path, leg):
    m = read_asf_amc(*leg, fps=60.0, length_unit=0.01)
    assert m.fps == 60.0
    np.testing.assert_allclose(m.root[0], [0, 0.18, 0])
    amc = LEG_AMC.replace(":DEGREES", ":RADIANS").replace("ltibia 90", f"ltibia {np.pi / 2!r}")
    r = read_asf_amc(leg[0], write(tmp_path, "rad.amc", amc))
    np.testing.assert_allclose(r.positions()[1], read_asf_amc(*leg).positions()[1], atol=1e-12)


def test_read_motion_finds_the_asf(leg):
    m = read_motion(leg[1])
    assert m.skeleton.names[1] == "lfemur"


def test_find_asf(tmp_path: Path):
    """CMU names motions SS_TT.amc and the subject's skeleton SS.asf."""
    write(tmp_path, "07.asf", LEG_ASF)
    amc = write(tmp_path, "07_03.amc", LEG_AMC)
    assert find_asf(amc) == tmp_path / "07.asf"
    other = write(tmp_path, "walk.amc", LEG_AMC)
    assert find_asf(other) == tmp_path / "07.asf"  # the folder's only ASF
    write(tmp_path, "walk.asf", LEG_ASF)
    assert find_asf(other) == tmp_path / "walk.asf"
    write(tmp_path, "08.asf", LEG_ASF)
    with pytest.raises(FileNotFoundError, match="no ASF"):
        find_asf(write(tmp_path, "09_01.amc", LEG_AMC))


CMU_BONES = {  # the 30 bones of the CMU skeleton, with their children
    "lhipjoint": ["lfemur"], "lfemur": ["ltibia"], "ltibia": ["lfoot"], "lfoot": ["ltoes"],
    "ltoes": [], "rhipjoint": ["rfemur"], "rfemur": ["rtibia"], "rtibia": ["rfoot"],
    "rfoot": ["rtoes"], "rtoes": [], "lowerback": ["upperback"], "upperback": ["thorax"],
    "thorax": ["lowerneck", "lclavicle", "rclavicle"], "lowerneck": ["upperneck"],
    "upperneck": ["head"], "head": [], "lclavicle": ["lhumerus"], "lhumerus": ["lradius"],
    "lradius": ["lwrist"], "lwrist": ["lhand", "lthumb"], "lhand": ["lfingers"],
    "lfingers": [], "lthumb": [], "rclavicle": ["rhumerus"], "rhumerus": ["rradius"],
    "rradius": ["rwrist"], "rwrist": ["rhand", "rthumb"], "rhand": ["rfingers"],
    "rfingers": [], "rthumb": [],
}


def cmu_asf() -> str:
    bones = "".join(
        f"  begin\n    id {i}\n    name {b}\n    direction 0 1 0\n    length 2\n"
        f"    axis 0 0 0 XYZ\n    dof rx ry rz\n    limits (-180 180) (-180 180) (-180 180)\n"
        f"  end\n" for i, b in enumerate(CMU_BONES, 1))
    links = "".join(f"    {b} {' '.join(kids)}\n" for b, kids in CMU_BONES.items() if kids)
    return (":units\n  length 0.45\n  angle deg\n:root\n  order TX TY TZ RX RY RZ\n  axis XYZ\n"
            "  position 0 0 0\n  orientation 0 0 0\n:bonedata\n" + bones
            + ":hierarchy\n  begin\n    root lhipjoint rhipjoint lowerback\n" + links + "  end\n")


def test_cmu_body_map(tmp_path: Path):
    sk = read_asf(write(tmp_path, "cmu.asf", cmu_asf()))
    assert sk.num_joints == 31
    bm = resolve_body_map(sk.names)  # strict: raises if any part is missing
    assert set(bm) == set(PARTS)
    assert bm == sk.body_map
    expected = {"pelvis": "root", "spine": "upperback", "chest": "thorax", "neck": "lowerneck",
                "head": "head"}
    for side, s in (("left", "l"), ("right", "r")):
        expected |= {f"{side}_hip": f"{s}femur", f"{side}_knee": f"{s}tibia",
                     f"{side}_ankle": f"{s}foot", f"{side}_toe": f"{s}toes",
                     f"{side}_shoulder": f"{s}humerus", f"{side}_elbow": f"{s}radius",
                     f"{side}_wrist": f"{s}wrist"}
    assert bm == expected


def test_cmu_full_motion(tmp_path: Path):
    asf = write(tmp_path, "cmu.asf", cmu_asf())
    rng = np.random.default_rng(0)
    frames = []
    for i in range(1, 4):
        frames.append(f"{i}\nroot " + " ".join(f"{v:.4f}" for v in rng.uniform(-30, 30, 6)))
        frames += [f"{b} " + " ".join(f"{v:.4f}" for v in rng.uniform(-90, 90, 3))
                   for b in CMU_BONES]
    m = read_asf_amc(asf, write(tmp_path, "cmu.amc", ":FULLY-SPECIFIED\n:DEGREES\n"
                                + "\n".join(frames) + "\n"))
    pos = m.positions()
    assert pos.shape == (3, 31, 3) and np.all(np.isfinite(pos))
    # rotations never change bone lengths: each joint stays 2 units from its parent's joint
    sk = m.skeleton
    for j in range(1, sk.num_joints):
        p = sk.parents[j]
        expected = 0.0 if p == 0 else 2 * U
        np.testing.assert_allclose(np.linalg.norm(pos[:, j] - pos[:, p], axis=-1), expected,
                                   atol=1e-12)


@pytest.mark.parametrize("which, old, new, line, words", [
    ("asf", "lfemur\n    direction 0 -1 0\n    length 9", "lfemur\n    direction 0 -1 0\n    length 9!",
     20, "number"),
    ("asf", "axis 0 0 90 XYZ", "axis 0 0 90 XYQ", 41, "axis order"),
    ("asf", "dof rx\n", "dof rx tx\n", 33, "unsupported dof"),
    ("asf", "    ltibia lfoot\n", "    ltibia lfoot\n    ltibia lknee\n", 50, "unknown bone"),
    ("asf", "    ltibia lfoot\n", "", 38, "not connected"),
    ("asf", "  end\n:hierarchy", ":hierarchy", 44, "expected 'end'"),
    ("asf", "limits (-10.0 170.0)", "limits (-10.0 170.0) (0 1)", 34, "limit pair"),
    ("amc", "ltibia 90", "ltibia 90 0", 12, "expected 1 values"),
    ("amc", "ltibia 90", "ltibia nan", 12, "finite number"),
    ("amc", "ltibia 90", "ltibia ninety", 12, "number"),
    ("amc", "ltibia 90", "lknee 90", 12, "unknown bone"),
    ("amc", "ltibia 90\n", "", 9, "no values for bone 'ltibia'"),
    ("amc", "\n3\n", "\n4\n", 14, "expected frame 3"),
    ("amc", "1\nroot", "root", 4, "frame number"),
])
def test_malformed(tmp_path: Path, which, old, new, line, words):
    asf, amc = LEG_ASF, LEG_AMC
    if which == "asf":
        assert asf.count(old) == 1
        asf = asf.replace(old, new)
    else:
        assert amc.count(old) == 1
        amc = amc.replace(old, new)
    a, b = write(tmp_path, "x.asf", asf), write(tmp_path, "x.amc", amc)
    with pytest.raises(FormatError) as e:
        read_asf_amc(a, b)
    assert e.value.path == str(a if which == "asf" else b)
    assert e.value.line == line, str(e.value)
    assert words in e.value.message


def test_empty_amc(tmp_path: Path, leg):
    with pytest.raises(FormatError, match="at least one frame"):
        read_asf_amc(leg[0], write(tmp_path, "e.amc", ":FULLY-SPECIFIED\n:DEGREES\n"))


TOKENS = ["begin", "end", ":root", ":bonedata", ":hierarchy", "root", "lfemur", "dof", "rx", "tx",
          "limits", "(", "inf", "nan", "axis", "XYZ", "\n", "1e999", "1e300", " ", "#", "(-1 1)",
          "length", "direction", "-1", ":RADIANS", "²"]


@st.composite
def mangled(draw, text: str) -> str:
    for _ in range(draw(st.integers(1, 3))):
        i = draw(st.integers(0, len(text)))
        j = draw(st.integers(i, min(len(text), i + 30)))
        piece = draw(st.one_of(st.sampled_from(TOKENS), st.text(max_size=6)))
        text = draw(st.sampled_from([text[:i] + text[j:], text[:i] + piece + text[i:],
                                     text[:i] + piece + text[j:], text[:i]]))
    return text


@settings(derandomize=True, max_examples=100, deadline=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(asf=st.one_of(mangled(LEG_ASF), st.just(LEG_ASF)), amc=mangled(LEG_AMC))
def test_parser_fails_only_with_format_error(tmp_path_factory, asf: str, amc: str):
    d = tmp_path_factory.getbasetemp()
    a, b = d / "fuzz.asf", d / "fuzz.amc"
    a.write_text(asf, encoding="utf-8", errors="surrogatepass")
    b.write_text(amc, encoding="utf-8", errors="surrogatepass")
    try:
        m = read_asf_amc(a, b)
    except FormatError as e:
        assert e.path in (str(a), str(b)) and e.message
        return
    assert np.all(np.isfinite(m.positions()))


def read_or_format_error(a: Path, b: Path) -> None:
    """The readers' contract: a valid Motion, or a FormatError naming one of the two files."""
    try:
        m = read_asf_amc(a, b)
    except FormatError as e:
        assert e.path in (str(a), str(b)) and e.message
        return
    assert m.num_frames >= 1 and np.all(np.isfinite(m.positions()))
    assert np.all(np.linalg.norm(m.skeleton.offsets, axis=-1) <= 10.0)


@settings(derandomize=True, max_examples=200, deadline=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(asf=st.one_of(mutations(LEG_ASF), st.just(LEG_ASF.encode())),
       amc=st.one_of(mutations(LEG_AMC), st.just(LEG_AMC.encode())))
def test_byte_mutations_fail_only_with_format_error(tmp_path_factory, asf: bytes, amc: bytes):
    d = tmp_path_factory.getbasetemp()
    a, b = d / "bytes.asf", d / "bytes.amc"
    a.write_bytes(asf)
    b.write_bytes(amc)
    read_or_format_error(a, b)


NUMBERS = st.one_of(st.floats().map(repr), st.integers().map(str), st.text(max_size=12),
                    st.sampled_from(["5e-324", "1e9", "0", "-1", "9" * 5000, "1e308"]))


@settings(derandomize=True, max_examples=150, deadline=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(unit=NUMBERS, length=NUMBERS, value=NUMBERS, frame=NUMBERS)
def test_malformed_units_lengths_values_and_frame_numbers(tmp_path_factory, unit: str,
                                                          length: str, value: str, frame: str):
    d = tmp_path_factory.getbasetemp()
    cases = [(LEG_ASF.replace("length 0.45", f"length {unit}"), LEG_AMC),
             (LEG_ASF.replace("length 4.5", f"length {length}"), LEG_AMC),
             (LEG_ASF, LEG_AMC.replace("ltibia 90", f"ltibia {value}")),
             (LEG_ASF, LEG_AMC.replace("\n1\n", f"\n{frame}\n"))]
    for i, (asf, amc) in enumerate(cases):
        a, b = d / f"f{i}.asf", d / f"f{i}.amc"
        a.write_text(asf, encoding="utf-8", errors="surrogatepass")
        b.write_text(amc, encoding="utf-8", errors="surrogatepass")
        read_or_format_error(a, b)


@pytest.mark.parametrize("which, old, new, words", [
    ("asf", "length 0.45", "length 5e-324", "length unit from 0.001 to 1000"),
    ("asf", "length 9\n", "length 1e9\n", "expected at most 10 m"),
    ("amc", "\n1\n", "\n" + "9" * 5000 + "\n", "frame number below 1e9"),
])
def test_implausible_values(tmp_path: Path, which, old, new, words):
    asf = LEG_ASF.replace(old, new, 1) if which == "asf" else LEG_ASF
    amc = LEG_AMC.replace(old, new, 1) if which == "amc" else LEG_AMC
    a, b = write(tmp_path, "x.asf", asf), write(tmp_path, "x.amc", amc)
    with pytest.raises(FormatError, match=words) as e:
        read_asf_amc(a, b)
    assert e.value.path == str(a if which == "asf" else b) and e.value.line is not None


def _many_bones(n: int, chain: bool) -> str:
    bones = "".join(f"  begin\n    id {i}\n    name b{i}\n    direction 0 1 0\n    length 1\n"
                    f"    axis 0 0 0 XYZ\n    dof rx\n  end\n" for i in range(n))
    links = "".join(f"    {'root' if i == 0 or not chain else f'b{i - 1}'} b{i}\n"
                    for i in range(n))
    return (":units\n  length 0.45\n:root\n  order TX TY TZ RX RY RZ\n  axis XYZ\n"
            f"  position 0 0 0\n  orientation 0 0 0\n:bonedata\n{bones}:hierarchy\n  begin\n"
            f"{links}  end\n")


@pytest.mark.parametrize("n, chain, words", [(300, True, "nested more than 256 deep"),
                                             (2100, False, "more than 1999 bones")])
def test_bone_limits(tmp_path: Path, n: int, chain: bool, words: str):
    """A body has far fewer bones, far less deeply nested: such files are refused at once (the
    fuzzing of issue 18 found 20,000 chained bones taking over a minute)."""
    a = write(tmp_path, "many.asf", _many_bones(n, chain))
    b = write(tmp_path, "many.amc", ":DEGREES\n1\nroot 0 0 0 0 0 0\n")
    with pytest.raises(FormatError, match=words) as e:
        read_asf_amc(a, b)
    assert e.value.path == str(a)


def test_a_long_amc_takes_memory_in_proportion_and_is_bounded(tmp_path: Path, leg,
                                                              monkeypatch):
    """A 1M-frame AMC took 1.9 GB (a dict of lists per frame) and a 185 MB one ended in
    MemoryError: values are kept as read, 8 bytes each, within MAX_JOINT_FRAMES."""
    import tracemalloc

    from imuloco.io import bvh

    asf, _ = leg
    frame = "root 0 18 0 0 0 0\nlfemur 0 0 0\nltibia 0\nlfoot 0 0\n"
    amc = write(tmp_path, "long.amc", ":DEGREES\n" + "".join(f"{k}\n{frame}"
                                                             for k in range(1, 20_001)))
    tracemalloc.start()
    motion = read_asf_amc(asf, amc)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert motion.num_frames == 20_000
    assert peak < 3 * amc.stat().st_size + 40 * motion.rotations.size  # text + arrays
    monkeypatch.setattr(bvh, "MAX_JOINT_FRAMES", 4 * 100)
    with pytest.raises(FormatError, match=r"long\.amc:\d+: 101 frames of 4 joints, more than "
                                          r"the 400 frames x joints"):
        read_asf_amc(asf, amc)
