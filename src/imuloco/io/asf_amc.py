"""ASF/AMC reading (the Acclaim format of the CMU motion capture database).

An ASF file describes the skeleton as bones: each has a rest ``direction`` (unit vector, world
axes) and ``length``, a local frame given by ``axis ax ay az ORDER``, and rotation ``dof``. An AMC
file gives, per frame, the root's translation and rotation and each bone's dof values.

Conventions (those of the CMU data and of the usual readers of it):

- Euler angles, in ``axis``, ``orientation``, the ``dof`` and the root ``order``, rotate about
  fixed axes in the order listed: ``axis 10 20 30 XYZ`` and ``dof rx ry rz`` both mean
  ``R = Rz Ry Rx`` (scipy's extrinsic ``"xyz"``).
- A bone's rotation relative to its parent, in world-aligned axes, is ``C M C^-1``, where ``C``
  is its ``axis`` frame and ``M`` its AMC rotation; the root's is the same with ``orientation``.
- Lengths: ``:units length L`` means file values are inches times ``L``; metres are
  ``value / L * 0.0254`` (CMU's ``L = 0.45`` gives 0.056444 m per unit, as the CMU FAQ says).
  Angles are degrees unless ``:units angle rad`` (ASF) or ``:RADIANS`` (AMC).
- The root's ``position`` is its rest position; the AMC translation channels replace it.

The Motion has one joint per bone, placed where the bone starts (its parent bone's end), with the
bone's rotation; joint 0 is the root. So ``lfemur`` is the hip joint, ``ltibia`` the knee,
``lfoot`` the ankle. A bone with no children keeps its end as an End Site. AMC files carry no
frame rate; the CMU data are 120 fps, the default here.
"""

from __future__ import annotations

import math
import re
from array import array
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from imuloco.core.motion import Motion
from imuloco.core.skeleton import Skeleton
from imuloco.errors import FormatError, MissingInputError
from imuloco.io.bvh import MAX_DEPTH, MAX_JOINTS, check_size, iter_lines
from imuloco.io.upaxis import check_skip, check_up, to_y_up
from imuloco.ops.rotations import IDENTITY, from_euler, qinv, qmul

INCH = 0.0254
CMU_FPS = 120.0
LENGTH_UNITS = (1e-3, 1e3)  # plausible ':units length L' (file values per inch)
MAX_BONE = 10.0  # metres: longer bones are corrupt data
MAX_LINE_CHARS = 1 << 16  # a bone's line holds a name and at most 6 numbers
_ROOT_CHANNELS = ("TX", "TY", "TZ", "RX", "RY", "RZ")
_BONE_DOF = ("rx", "ry", "rz")


@dataclass
class _Bone:
    name: str
    line: int
    direction: np.ndarray | None = None
    length: float | None = None
    axis: np.ndarray = field(default_factory=lambda: np.zeros(3))
    axis_order: str = "XYZ"
    dof: list[str] = field(default_factory=list)
    limits: int = 0
    limits_line: int = 0
    parent: str | None = None
    children: list[str] = field(default_factory=list)


@dataclass
class _Asf:
    path: Path
    length: float = 1.0  # ':units length L': a file value is L times the length in inches
    degrees: bool = True
    root_order: list[str] = field(default_factory=lambda: list(_ROOT_CHANNELS))
    root_axis: str = "XYZ"
    position: np.ndarray = field(default_factory=lambda: np.zeros(3))
    orientation: np.ndarray = field(default_factory=lambda: np.zeros(3))
    bones: dict[str, _Bone] = field(default_factory=dict)
    root_children: list[str] = field(default_factory=list)
    order: list[str] = field(default_factory=list)  # bones, parents before children


def _lines(path: Path) -> Iterator[tuple[int, list[str]]]:
    """(1-based line number, tokens) of each line that has tokens once comments are removed,
    lazily: a parser that stops at a limit does not split the rest of a huge file."""
    raw = path.read_bytes()
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = raw.decode("latin-1")
    del raw
    for i, ln in enumerate(iter_lines(text)):
        if len(ln) > MAX_LINE_CHARS:  # its tokens would take 30 times its length
            raise FormatError(path, i + 1, f"a line of {len(ln):,} characters, more than "
                              f"{MAX_LINE_CHARS:,}: not an ASF/AMC line")
        toks = ln.split("#", 1)[0].split()
        if toks:
            yield i + 1, toks


def _num(path: Path, line: int, tok: str, what: str, allow_inf: bool = False) -> float:
    try:
        v = float(tok)
    except ValueError:
        raise FormatError(path, line, f"expected a number for {what}, found {tok!r}") from None
    if math.isnan(v) or (math.isinf(v) and not allow_inf) or (math.isfinite(v) and abs(v) > 1e9):
        raise FormatError(path, line, f"expected a finite number for {what}, found {tok!r}")
    return v


def _nums(path: Path, line: int, toks: list[str], n: int, what: str) -> np.ndarray:
    if len(toks) != n:
        raise FormatError(path, line, f"expected {n} numbers for {what}, found {len(toks)}")
    return np.array([_num(path, line, t, what) for t in toks])


def _order(path: Path, line: int, tok: str, what: str) -> str:
    if sorted(tok.upper()) != ["X", "Y", "Z"]:
        raise FormatError(path, line, f"expected an axis order such as XYZ for {what}, "
                          f"found {tok!r}")
    return tok.upper()


def _parse_asf(path: Path) -> _Asf:
    asf = _Asf(path)
    section: str | None = None
    bone: _Bone | None = None
    in_block = False  # inside begin ... end of :bonedata or :hierarchy
    last_key = ""
    line = 1
    for line, toks in _lines(path):
        key = toks[0]
        if key.startswith(":"):
            if in_block:
                raise FormatError(path, line, f"expected 'end' before {key}")
            section, args = key[1:].lower(), toks[1:]
            if section in ("units", "root") and args:
                toks = args  # an entry written on the keyword's line
                key = toks[0]
            else:
                continue
        if section is None:
            raise FormatError(path, line, f"expected a ':' keyword such as :units, found {key!r}")
        if section == "units":
            if key == "length":
                asf.length = _num(path, line, toks[1] if len(toks) > 1 else "", "length unit")
                if not LENGTH_UNITS[0] <= asf.length <= LENGTH_UNITS[1]:
                    raise FormatError(path, line, f"expected a length unit from "
                                      f"{LENGTH_UNITS[0]:g} to {LENGTH_UNITS[1]:g} (CMU: 0.45), "
                                      f"found {toks[1]!r}")
            elif key == "angle":
                unit = toks[1].lower() if len(toks) > 1 else ""
                if unit not in ("deg", "rad"):
                    raise FormatError(path, line, f"expected 'angle deg' or 'angle rad', "
                                      f"found {' '.join(toks)!r}")
                asf.degrees = unit == "deg"
        elif section == "root":
            if key == "order":
                chans = [t.upper() for t in toks[1:]]
                if any(c not in _ROOT_CHANNELS for c in chans) or len(set(chans)) != len(chans):
                    raise FormatError(path, line, f"expected distinct root channels among "
                                      f"{list(_ROOT_CHANNELS)}, found {toks[1:]}")
                asf.root_order = chans
            elif key == "axis":
                if len(toks) != 2:
                    raise FormatError(path, line, "expected 'axis' and an order such as XYZ")
                asf.root_axis = _order(path, line, toks[1], "the root axis")
            elif key == "position":
                asf.position = _nums(path, line, toks[1:], 3, "the root position")
            elif key == "orientation":
                asf.orientation = _nums(path, line, toks[1:], 3, "the root orientation")
            else:
                raise FormatError(path, line, f"expected order, axis, position or orientation "
                                  f"in :root, found {key!r}")
        elif section == "bonedata":
            if not in_block:
                if key != "begin":
                    raise FormatError(path, line, f"expected 'begin' of a bone, found {key!r}")
                in_block, bone, last_key = True, _Bone("", line), ""
                continue
            assert bone is not None
            if key == "end":
                _close_bone(asf, bone, line)
                in_block, bone = False, None
            elif key == "name":
                if len(toks) != 2:
                    raise FormatError(path, line, "expected 'name' and one bone name")
                bone.name, bone.line = toks[1], line
            elif key == "direction":
                bone.direction = _nums(path, line, toks[1:], 3, "the bone direction")
            elif key == "length":
                bone.length = float(_nums(path, line, toks[1:], 1, "the bone length")[0])
                if bone.length < 0:
                    raise FormatError(path, line, "expected a non-negative bone length")
            elif key == "axis":
                if len(toks) != 5:
                    raise FormatError(path, line, "expected 'axis ax ay az ORDER'")
                bone.axis = _nums(path, line, toks[1:4], 3, "the bone axis")
                bone.axis_order = _order(path, line, toks[4], "the bone axis")
            elif key == "dof":
                dof = [t.lower() for t in toks[1:]]
                bad = [d for d in dof if d not in _BONE_DOF]
                if bad:
                    raise FormatError(path, line, f"unsupported dof {bad} on a bone; expected "
                                      f"rotations among {list(_BONE_DOF)} (only the root "
                                      "translates)")
                if len(set(dof)) != len(dof):
                    raise FormatError(path, line, f"repeated dof in {toks[1:]}")
                bone.dof = dof
            elif key == "limits" or (key.startswith("(") and last_key == "limits"):
                text = " ".join(toks[1:] if key == "limits" else toks)
                for lo, hi in re.findall(r"\(\s*([^\s()]+)\s+([^\s()]+)\s*\)", text):
                    _num(path, line, lo, "a lower limit", allow_inf=True)
                    _num(path, line, hi, "an upper limit", allow_inf=True)
                    bone.limits += 1
                    bone.limits_line = line
                key = "limits"
            elif key not in ("id", "bodymass", "cofmass"):
                raise FormatError(path, line, f"expected id, name, direction, length, axis, dof "
                                  f"or limits in a bone, found {key!r}")
            last_key = key
        elif section == "hierarchy":
            if not in_block:
                if key != "begin":
                    raise FormatError(path, line, f"expected 'begin' of the hierarchy, "
                                      f"found {key!r}")
                in_block = True
                continue
            if key == "end":
                in_block = False
                continue
            _link(asf, line, key, toks[1:])
    if in_block:
        raise FormatError(path, line, f"file ends early: expected 'end' of the :{section} block")
    _order_bones(asf)
    return asf


def _close_bone(asf: _Asf, bone: _Bone, line: int) -> None:
    path = asf.path
    if not bone.name:
        raise FormatError(path, line, "bone block ends without a 'name'")
    if bone.name in asf.bones or bone.name == "root":
        raise FormatError(path, bone.line, f"bone name {bone.name!r} is used twice")
    if len(asf.bones) + 1 >= MAX_JOINTS:
        raise FormatError(path, bone.line, f"more than {MAX_JOINTS - 1} bones; expected a "
                          "body's skeleton")
    for what in ("direction", "length"):
        if getattr(bone, what) is None:
            raise FormatError(path, line, f"bone {bone.name!r} has no {what!r}")
    assert bone.direction is not None and bone.length is not None
    norm = float(np.linalg.norm(bone.direction))
    if norm == 0 and bone.length > 0:
        raise FormatError(path, line, f"bone {bone.name!r} has a zero direction")
    bone.direction = bone.direction / norm if norm > 0 else bone.direction
    if bone.limits and bone.limits != len(bone.dof):
        raise FormatError(path, bone.limits_line, f"bone {bone.name!r}: expected one limit "
                          f"pair per dof ({len(bone.dof)}), found {bone.limits}")
    asf.bones[bone.name] = bone


def _link(asf: _Asf, line: int, parent: str, children: list[str]) -> None:
    path = asf.path
    if parent != "root" and parent not in asf.bones:
        raise FormatError(path, line, f"hierarchy names an unknown parent {parent!r}")
    for c in children:
        if c not in asf.bones:
            raise FormatError(path, line, f"hierarchy names an unknown bone {c!r}")
        if asf.bones[c].parent is not None:
            raise FormatError(path, line, f"bone {c!r} has two parents in the hierarchy")
        asf.bones[c].parent = parent
        (asf.root_children if parent == "root" else asf.bones[parent].children).append(c)


def _order_bones(asf: _Asf) -> None:
    stack = [(b, 1) for b in reversed(asf.root_children)]
    while stack:  # depth first, children in the order the hierarchy lists them
        b, depth = stack.pop()
        if depth > MAX_DEPTH:
            raise FormatError(asf.path, asf.bones[b].line, f"bones nested more than "
                              f"{MAX_DEPTH} deep; expected a body's skeleton")
        asf.order.append(b)
        stack.extend((c, depth + 1) for c in reversed(asf.bones[b].children))
    ordered = set(asf.order)
    missing = [b for b in asf.bones.values() if b.name not in ordered]
    if missing:
        raise FormatError(asf.path, missing[0].line, f"bones {[b.name for b in missing]} are "
                          "not connected to the root in the :hierarchy")


def _skeleton(asf: _Asf, scale: float) -> Skeleton:
    names = ["root"] + asf.order
    index = {n: i for i, n in enumerate(names)}
    parents = np.array([-1] + [index[asf.bones[b].parent or "root"] for b in asf.order])
    offsets = np.zeros((len(names), 3))
    end_sites = {}
    for b in asf.order:
        bone = asf.bones[b]
        vec = bone.direction * bone.length * scale  # the bone, from its start to its end
        if not bone.length * scale <= MAX_BONE:
            raise FormatError(asf.path, bone.line, f"bone {b!r} is {bone.length * scale:.3g} m "
                              f"long; expected at most {MAX_BONE:g} m (check its length and "
                              "the length unit)")
        for c in bone.children:
            offsets[index[c]] = vec
        if not bone.children:
            end_sites[index[b]] = vec
    return Skeleton(names, parents, offsets, end_sites)


def read_asf(path: str | Path, length_unit: float | None = None) -> Skeleton:
    """Read an ASF skeleton (rest pose, metres).

    Parameters
    ----------
    length_unit : metres per ASF length unit; default ``0.0254 / L`` from ``:units length L``.
    """
    asf = _parse_asf(Path(path))
    return _skeleton(asf, length_unit if length_unit is not None else INCH / asf.length)


def _parse_amc(path: Path, channels: dict[str, list[str]], degrees: bool
               ) -> tuple[dict[str, np.ndarray], bool, int]:
    """Per bone, its values (T, n_dof); whether angles are degrees; the frame count T. Values
    are kept as read, 8 bytes each (a list of dicts per frame took 1.9 GB for 1M frames), and
    at most :data:`imuloco.io.bvh.MAX_JOINT_FRAMES` frames x joints."""
    starts, width = {}, 0  # each bone's first column in a frame's row
    for name, want in channels.items():
        starts[name], width = width, width + len(want)
    values, count, frames_start = array("d"), 0, 0
    row, seen, frame_line = np.empty(width), set(), 0

    def end_frame() -> None:
        for name, want in channels.items():
            if want and name not in seen:
                raise FormatError(path, frame_line, f"frame has no values for bone {name!r} "
                                  f"({' '.join(want)})")
        values.frombytes(row.tobytes())

    for line, toks in _lines(path):
        key = toks[0]
        if key.startswith(":"):
            if key.upper() in (":DEGREES", ":RADIANS"):
                degrees = key.upper() == ":DEGREES"
            continue
        if len(toks) == 1 and key.isascii() and key.isdigit():
            if len(key.lstrip("0")) > 9:
                raise FormatError(path, line, f"expected a frame number below 1e9, found "
                                  f"{key[:40]!r}")
            number = int(key)
            if count and number != frames_start + count:
                raise FormatError(path, line, f"expected frame {frames_start + count}, "
                                  f"found frame {number}")
            if count:
                end_frame()
            else:
                frames_start = number
            count += 1
            check_size(path, line, count, len(channels))
            seen.clear()
            frame_line = line
            continue
        if not count:
            raise FormatError(path, line, f"expected a frame number before bone values, "
                              f"found {key!r}")
        if key not in channels:
            raise FormatError(path, line, f"unknown bone {key!r}; the ASF has "
                              f"{list(channels)}")
        if key in seen:
            raise FormatError(path, line, f"bone {key!r} appears twice in one frame")
        want = channels[key]
        if len(toks) - 1 != len(want):
            raise FormatError(path, line, f"expected {len(want)} values for {key!r} "
                              f"({' '.join(want)}), found {len(toks) - 1}")
        row[starts[key]:starts[key] + len(want)] = [
            _num(path, line, t, f"{key} {w}") for t, w in zip(toks[1:], want)]
        seen.add(key)
    if not count:
        raise FormatError(path, None, "expected at least one frame, found none")
    end_frame()
    table = np.frombuffer(values, dtype=np.float64).reshape(count, width)
    out = {name: table[:, starts[name]:starts[name] + len(want)].copy()
           for name, want in channels.items() if want}
    return out, degrees, count


def _fixed_axes(angles: np.ndarray, order: str, degrees: bool) -> np.ndarray:
    """Rotations about fixed axes, the first of ``order`` (e.g. ``"xyz"``) applied first:
    the intrinsic rotation in the reversed order. angles : (..., len(order)) -> (..., 4)."""
    return from_euler(np.asarray(angles)[..., ::-1], order[::-1].upper(), degrees=degrees)


def _conjugated(c: np.ndarray, m: np.ndarray) -> np.ndarray:
    """``C M C^-1``: a rotation ``m`` (T, 4) about axes given by the frame ``c`` (4,)."""
    return qmul(qmul(c, m), qinv(c))


def find_asf(amc_path: str | Path) -> Path:
    """The ASF skeleton of an AMC motion: ``NAME.asf`` beside it, else the CMU layout's
    ``SS.asf`` for ``SS_TT.amc``, else the only ASF in its folder."""
    amc_path = Path(amc_path)
    folder = amc_path.parent
    for cand in (amc_path.with_suffix(".asf"), folder / f"{amc_path.stem.split('_')[0]}.asf"):
        if cand.is_file():
            return cand
    found = sorted(folder.glob("*.asf")) + sorted(folder.glob("*.ASF"))
    if len(set(found)) == 1:
        return found[0]
    raise MissingInputError(f"{amc_path}: no ASF skeleton found beside it (looked for "
                            f"{amc_path.stem}.asf, {amc_path.stem.split('_')[0]}.asf, or a "
                            f"single .asf in {folder}); pass the ASF path explicitly")


def read_asf_amc(asf_path: str | Path, amc_path: str | Path, fps: float = CMU_FPS,
                 length_unit: float | None = None, up: str = "auto",
                 skip_frames: int = 0) -> Motion:
    """Read a CMU-style ASF skeleton and AMC motion as a Motion in metres.

    Parameters
    ----------
    asf_path, amc_path : the skeleton and motion files.
    fps : frame rate; AMC files do not store one (CMU captured at 120 fps).
    length_unit : metres per ASF length unit; default ``0.0254 / L`` from ``:units length L``.
    up : the vertical axis, ``"y"`` (CMU's), ``"z"`` or ``"auto"`` (see
        :mod:`imuloco.io.upaxis`); Z-up motion is turned Y up.
    skip_frames : leading frames to drop.

    Raises
    ------
    FormatError : naming the file, line and what was expected.
    """
    asf_path, amc_path = Path(asf_path), Path(amc_path)
    if not fps > 0:
        raise ValueError(f"fps must be positive, got {fps}")
    up = check_up(up)
    asf = _parse_asf(asf_path)
    scale = length_unit if length_unit is not None else INCH / asf.length
    skeleton = _skeleton(asf, scale)
    channels = {"root": asf.root_order} | {b: asf.bones[b].dof for b in asf.order}
    values, degrees, t = _parse_amc(amc_path, channels, asf.degrees)
    check_skip(skip_frames, t, amc_path)
    values = {k: v[skip_frames:] for k, v in values.items()}
    t -= skip_frames

    rotations = np.tile(IDENTITY, (t, skeleton.num_joints, 1))
    root = np.tile(asf.position, (t, 1))
    if "root" in values:
        rv = values["root"]
        for i, ch in enumerate(asf.root_order):
            if ch[0] == "T":
                root[:, "XYZ".index(ch[1])] = rv[:, i]
        rot = [i for i, ch in enumerate(asf.root_order) if ch[0] == "R"]
        if rot:
            order = "".join(asf.root_order[i][1].lower() for i in rot)
            c = _fixed_axes(asf.orientation, asf.root_axis, asf.degrees)
            rotations[:, 0] = _conjugated(c, _fixed_axes(rv[:, rot], order, degrees))
    for j, b in enumerate(asf.order, start=1):
        bone = asf.bones[b]
        if bone.dof:
            c = _fixed_axes(bone.axis, bone.axis_order, asf.degrees)
            m = _fixed_axes(values[b], "".join(d[1] for d in bone.dof), degrees)
            rotations[:, j] = _conjugated(c, m)
    try:
        motion = Motion(skeleton, rotations, root * scale, fps, amc_path.stem)
    except ValueError as e:  # values overflowing once scaled; each was checked finite
        raise FormatError(amc_path, None, f"{e}; expected plausible values") from None
    return to_y_up(motion, up, amc_path)
