"""BVH (Biovision Hierarchy) reading and writing.

Any channel layout is read: position and rotation channels on any joint, in any Euler order
(BVH rotation channels are intrinsic: the first listed is applied first from the parent's side).
Constant position channels on non-root joints become that joint's offset. A static root whose
single child carries the translation (as ``joint_Root`` and ``Hips`` in the Bandai-Namco data)
is folded into that child, so the Motion's root is the pelvis. Files keep their units: the
reader scales to metres (``unit="auto"`` guesses cm when the legs are longer than 3 units), the
writer writes centimetres by default.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from imuloco.core.motion import Motion
from imuloco.core.skeleton import Skeleton
from imuloco.io.errors import FormatError
from imuloco.ops.rotations import IDENTITY, from_euler, qmul, qrot, to_euler

UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254}
_ROT = {"Xrotation": "X", "Yrotation": "Y", "Zrotation": "Z"}
_POS = {"Xposition": 0, "Yposition": 1, "Zposition": 2}


@dataclass
class _Joint:
    name: str
    parent: int
    offset: np.ndarray
    channels: list[str] = field(default_factory=list)
    end_site: np.ndarray | None = None


class _Tokens:
    """Whitespace tokens with their line numbers, for error messages."""

    def __init__(self, path: Path, lines: list[str]) -> None:
        self.path = path
        self.items = [(tok, i + 1) for i, ln in enumerate(lines) for tok in ln.split()]
        self.pos = 0

    def next(self, expected: str) -> tuple[str, int]:
        if self.pos >= len(self.items):
            last = self.items[-1][1] if self.items else 1
            raise FormatError(self.path, last, f"file ends early: expected {expected}")
        tok = self.items[self.pos]
        self.pos += 1
        return tok

    def expect(self, word: str) -> int:
        tok, line = self.next(repr(word))
        if tok != word:
            raise FormatError(self.path, line, f"expected {word!r}, found {tok!r}")
        return line

    def number(self, what: str) -> float:
        tok, line = self.next(what)
        try:
            value = float(tok)
        except ValueError:
            raise FormatError(self.path, line, f"expected a number for {what}, found {tok!r}") from None
        if not math.isfinite(value):
            raise FormatError(self.path, line, f"expected a finite number for {what}, found {tok}")
        return value


def _parse_hierarchy(tk: _Tokens) -> list[_Joint]:
    joints: list[_Joint] = []
    tk.expect("HIERARCHY")
    tok, line = tk.next("ROOT")
    if tok != "ROOT":
        raise FormatError(tk.path, line, f"expected 'ROOT', found {tok!r}")

    def joint(parent: int) -> None:
        name, line = tk.next("a joint name")
        tk.expect("{")
        tk.expect("OFFSET")
        off = np.array([tk.number("OFFSET x"), tk.number("OFFSET y"), tk.number("OFFSET z")])
        j = _Joint(name, parent, off)
        joints.append(j)
        me = len(joints) - 1
        tk.expect("CHANNELS")
        tok, line = tk.next("a channel count")
        if not tok.isdigit():
            raise FormatError(tk.path, line, f"expected a channel count, found {tok!r}")
        for _ in range(int(tok)):
            ch, line = tk.next("a channel name")
            if ch not in _ROT and ch not in _POS:
                raise FormatError(tk.path, line, f"unknown channel {ch!r} on joint {name!r}; "
                                  f"expected one of {sorted(_POS) + sorted(_ROT)}")
            j.channels.append(ch)
        while True:
            tok, line = tk.next("JOINT, End Site or '}'")
            if tok == "JOINT":
                joint(me)
            elif tok == "End":
                tk.expect("Site")
                tk.expect("{")
                tk.expect("OFFSET")
                j.end_site = np.array([tk.number("End Site x"), tk.number("End Site y"),
                                       tk.number("End Site z")])
                tk.expect("}")
            elif tok == "}":
                return
            else:
                raise FormatError(tk.path, line, f"expected JOINT, End Site or '}}', found {tok!r}")

    joint(-1)
    return joints


def read_bvh(path: str | Path, unit: str = "auto", fold_static_root: bool = True) -> Motion:
    """Read a BVH file as a Motion in metres.

    Parameters
    ----------
    path : the .bvh file.
    unit : the file's length unit, one of ``m, cm, mm, in`` or ``auto``.
    fold_static_root : fold a root that never moves into its single moving child.

    Raises
    ------
    FormatError : naming the file, line and what was expected.
    """
    path = Path(path)
    try:
        text = path.read_text()
    except UnicodeDecodeError as e:
        raise FormatError(path, None, f"not a text BVH file ({e})") from None
    lines = text.splitlines()
    motion_at = next((i for i, ln in enumerate(lines) if ln.strip() == "MOTION"), None)
    if motion_at is None:
        raise FormatError(path, len(lines), "expected a MOTION section after the HIERARCHY")
    joints = _parse_hierarchy(_Tokens(path, lines[:motion_at]))
    frames, frame_time, data = _parse_motion(path, lines, motion_at, joints)

    scale = UNITS.get(unit) if unit != "auto" else None
    if unit != "auto" and scale is None:
        raise ValueError(f"unit must be one of {sorted(UNITS)} or 'auto', got {unit!r}")
    fps = 1.0 / frame_time
    if abs(fps - round(fps)) < 1e-3:  # "0.0333333" means 30 fps, not 30.00003
        fps = float(round(fps))
    return _build_motion(path, joints, data, fps, scale, fold_static_root)


def _parse_motion(path: Path, lines: list[str], at: int, joints: list[_Joint]
                  ) -> tuple[int, float, np.ndarray]:
    def field_value(i: int, key: str) -> str:
        if i >= len(lines) or not lines[i].strip().startswith(key):
            raise FormatError(path, i + 1, f"expected '{key}' line")
        return lines[i].split(":", 1)[1].strip()

    frames_s = field_value(at + 1, "Frames:")
    ft_s = field_value(at + 2, "Frame Time:")
    try:
        frames, frame_time = int(frames_s), float(ft_s)
    except ValueError:
        raise FormatError(path, at + 2, "expected an integer frame count and a frame time") from None
    if frames < 1 or not frame_time > 0:
        raise FormatError(path, at + 2, "expected at least one frame and a positive frame time")
    width = sum(len(j.channels) for j in joints)
    body = [(i + 1, ln) for i, ln in enumerate(lines[at + 3:], start=at + 3) if ln.strip()]
    if len(body) < frames:
        last = body[-1][0] if body else at + 3
        raise FormatError(path, last, f"truncated MOTION block: header says {frames} frames, "
                          f"found {len(body)}")
    data = np.empty((frames, width))
    for row, (lineno, ln) in enumerate(body[:frames]):
        parts = ln.split()
        if len(parts) != width:
            raise FormatError(path, lineno, f"expected {width} channel values, found {len(parts)}")
        try:
            data[row] = [float(p) for p in parts]
        except ValueError:
            bad = next(p for p in parts if not _is_float(p))
            raise FormatError(path, lineno, f"expected a number, found {bad!r}") from None
        if not np.all(np.isfinite(data[row])):
            raise FormatError(path, lineno, "expected finite numbers, found NaN or inf")
    return frames, frame_time, data


def _is_float(s: str) -> bool:
    try:
        float(s)
        return True
    except ValueError:
        return False


def _build_motion(path: Path, joints: list[_Joint], data: np.ndarray, fps: float,
                  scale: float | None, fold_static_root: bool) -> Motion:
    t = data.shape[0]
    n = len(joints)
    local_pos = np.empty((t, n, 3))
    local_rot = np.empty((t, n, 4))
    col = 0
    for k, j in enumerate(joints):
        local_pos[:, k] = j.offset
        rot_order = "".join(_ROT[c] for c in j.channels if c in _ROT)
        rot_cols = [col + i for i, c in enumerate(j.channels) if c in _ROT]
        for i, c in enumerate(j.channels):
            if c in _POS:
                local_pos[:, k, _POS[c]] = data[:, col + i]
        local_rot[:, k] = (from_euler(data[:, rot_cols], rot_order) if rot_order
                           else IDENTITY)
        col += len(j.channels)

    names = [j.name for j in joints]
    parents = np.array([j.parent for j in joints])
    first = 0
    if (fold_static_root and n > 1 and len([j for j in joints if j.parent == 0]) == 1
            and np.ptp(local_pos[:, 0], axis=0).max() < 1e-9
            and np.ptp(local_rot[:, 0], axis=0).max() < 1e-9):
        # The child's world transform is the static root's transform applied to its own.
        local_pos[:, 1] = local_pos[:, 0] + qrot(local_rot[:, 0], local_pos[:, 1])
        local_rot[:, 1] = qmul(local_rot[:, 0], local_rot[:, 1])
        first = 1
    for k in range(first + 1, n):
        if np.ptp(local_pos[:, k], axis=0).max() > 1e-6 * max(1.0, np.abs(local_pos[:, k]).max()):
            raise FormatError(path, None, f"joint {names[k]!r} has moving position channels; "
                              "only the root may translate")

    offsets = local_pos[0].copy()
    if scale is None:
        legs = [np.linalg.norm(offsets[k]) for k in range(first + 1, n)]
        scale = 0.01 if sum(sorted(legs)[-4:]) > 3.0 else 1.0
    end_sites = {k - first: j.end_site * scale for k, j in enumerate(joints)
                 if j.end_site is not None and k >= first}
    offsets[first] = 0.0
    skeleton = Skeleton(names[first:], np.where(parents[first:] >= 0, parents[first:] - first, -1),
                        offsets[first:] * scale, end_sites)
    return Motion(skeleton, local_rot[:, first:], local_pos[:, first] * scale, fps, path.stem)


def write_bvh(motion: Motion, path: str | Path, unit: str = "cm", order: str = "ZXY",
              overwrite: bool = False) -> Path:
    """Write a Motion as BVH: 6 channels on the root, 3 rotation channels elsewhere, Euler
    ``order`` (intrinsic), lengths in ``unit``. Refuses to replace an existing file unless
    ``overwrite``. Returns the path written."""
    path = Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists; pass overwrite=True (or --force) to replace it")
    if unit not in UNITS:
        raise ValueError(f"unit must be one of {sorted(UNITS)}, got {unit!r}")
    k = 1.0 / UNITS[unit]
    sk = motion.skeleton
    order = order.upper()
    rot_channels = " ".join(f"{a}rotation" for a in order)
    out: list[str] = ["HIERARCHY"]

    def emit(j: int, depth: int) -> None:
        pad = "\t" * depth
        kind = "ROOT" if j == 0 else "JOINT"
        out.append(f"{pad}{kind} {sk.names[j]}")
        out.append(f"{pad}{{")
        out.append(f"{pad}\tOFFSET " + " ".join(f"{v:.6f}" for v in sk.offsets[j] * k))
        chans = ("Xposition Yposition Zposition " if j == 0 else "") + rot_channels
        out.append(f"{pad}\tCHANNELS {6 if j == 0 else 3} {chans}")
        kids = sk.children(j)
        for c in kids:
            emit(c, depth + 1)
        if not kids or j in sk.end_sites:
            site = sk.end_sites.get(j, np.zeros(3)) * k
            out.extend([f"{pad}\tEnd Site", f"{pad}\t{{",
                        f"{pad}\t\tOFFSET " + " ".join(f"{v:.6f}" for v in site), f"{pad}\t}}"])
        out.append(f"{pad}}}")

    emit(0, 0)
    eul = to_euler(motion.rotations, order)  # (T, J, 3)
    values = np.concatenate([motion.root * k, eul.reshape(motion.num_frames, -1)], axis=1)
    out += ["MOTION", f"Frames: {motion.num_frames}", f"Frame Time: {1.0 / motion.fps:.8f}"]
    out += [" ".join(f"{v:.6f}" for v in row) for row in values]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(out) + "\n")
    return path
