"""BVH (Biovision Hierarchy) reading and writing.

Any channel layout is read: position and rotation channels on any joint, in any order and any
Euler order (BVH rotation channels are intrinsic: the first listed is applied first from the
parent's side, so ``Zrotation Xrotation Yrotation`` is ``R = Rz Rx Ry``). Position channels
replace the joint's OFFSET; constant ones on non-root joints (as in files with 6 channels on
every joint) become that joint's offset. A :class:`Motion` translates its root only, so a root
whose single child has position channels is folded into that child (the child's world path is
the root's transform applied to its own) when the root never moves (``joint_Root`` above
``Hips`` in the Bandai-Namco data) or the child's translation moves (``Hips`` in
bandai-namco-1's ``normal`` style), repeatedly down a chain of single children; moving
translations below a branching joint are refused.

Root position channels replace the root's OFFSET, as the format says and Blender reads it; some
exporters (iClone, in 26 clips of ``cmu-iclone``) mean them to be added to it: ``root_offset``
chooses, and by default the OFFSET is added when that puts the body's lowest joint nearer the
floor (height 0). Z-up files are turned Y up (:mod:`imuloco.io.upaxis`).

Files keep their units: the reader scales to metres and the writer writes centimetres by default.
``unit="auto"`` guesses from the leg (hip to ankle) when the body map finds one: under 3 units is
metres, under 30 the CMU unit (1/0.45 inch, the CMU BVH conversions), under 300 centimetres,
else millimetres; without a leg, centimetres when the four longest bones add up to more than 3
units, else metres. Inches are never guessed: pass ``unit="in"``.
"""

from __future__ import annotations

import decimal
import functools
import math
import re
from array import array
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from imuloco.core.bodymap import resolve_body_map
from imuloco.core.motion import Motion
from imuloco.core.skeleton import Skeleton
from imuloco.errors import FormatError, InputError, excerpt
from imuloco.io.atomic import atomic_write, check_output
from imuloco.io.numtext import read_grid
from imuloco.io.upaxis import (
    Z_TO_Y,
    check_skip,
    check_up,
    median,
    resolve_up,
    spread_index,
    to_y_up,
)
from imuloco.ops.kinematics import fk, joint_positions
from imuloco.ops.rotations import IDENTITY, euler_components, qmul, qrot, to_euler

# Metres per file unit. "cmu": the CMU motion capture unit, (1 / 0.45) inch.
UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254, "cmu": 0.0254 / 0.45}
CHANNELS = ("Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation")
_CANON = {c.lower(): c for c in CHANNELS}  # "XROTATION" and "XRotation" are seen in the wild
MIN_FPS, MAX_FPS = 1.0, 1000.0  # plausible frame rates; others are corrupt headers
MAX_FRAMES = 10_000_000  # 23 hours at 120 fps
MAX_JOINTS, MAX_DEPTH = 2_000, 256  # rigs with face and finger bones have a few hundred
# The fast reading takes "\n" and "\r\n" only; str.splitlines also breaks at these (ASCII
# ones first).
_ODD_BREAKS = "\x0b\x0c\x1c\x1d\x1e\x85\u2028\u2029"
_MOTION = re.compile(r"^[ \t]*MOTION[ \t]*\r?$", re.MULTILINE)
_HEADERS = re.compile(r"(?:[ \t]*\r?\n)*[ \t]*Frames[ \t]*:[ \t]*(\S+)[ \t]*\r?\n"
                      r"(?:[ \t]*\r?\n)*[ \t]*Frame Time[ \t]*:[ \t]*(\S+)[ \t]*\r?\n")
_MAX_ABS = 1e9  # larger numbers are corrupt data in any unit, and would overflow products
# Euler angles whose conversion costs about as much as a conversion call's own overhead (sines
# and cosines of 4,096 angles, 0.1-0.2 ms; measured in the issue 22 work)
_CALL_ANGLES = 4096


@dataclass
class _Joint:
    name: str
    parent: int
    line: int
    offset: np.ndarray = field(default_factory=lambda: np.zeros(3))
    channels: list[str] = field(default_factory=list)
    end_site: np.ndarray | None = None


class _Tokens:
    """Whitespace tokens with their line numbers, for error messages, found as they are read:
    a huge line (80 MB of ``0 ``) costs no memory beyond the text (a list of its tokens took
    3.4 GB)."""

    def __init__(self, path: Path, lines: Iterable[str] | Iterable[tuple[int, str]]) -> None:
        self.path = path
        self._items = ((m.group(), i) for i, ln in _numbered(lines)
                       for m in _TOKEN.finditer(ln))
        self._next: tuple[str, int] | None = next(self._items, None)
        self.line = 1  # the line of the last token read

    def peek(self) -> str | None:
        return None if self._next is None else self._next[0]

    def next(self, expected: str) -> tuple[str, int]:
        if self._next is None:
            raise FormatError(self.path, self.line, f"file ends early: expected {expected}")
        tok = self._next
        self._next = next(self._items, None)
        self.line = tok[1]
        return tok

    def rest_of_line(self, line: int) -> list[str]:
        """The remaining tokens on ``line`` (joint names may contain spaces), at most
        :data:`MAX_NAME_WORDS`."""
        out = []
        while self._next is not None and self._next[1] == line:
            if len(out) == MAX_NAME_WORDS:
                raise FormatError(self.path, line, f"more than {MAX_NAME_WORDS} words after "
                                  "ROOT/JOINT; expected a joint name")
            out.append(self.next("a joint name")[0])
        return out

    def expect(self, word: str) -> int:
        tok, line = self.next(repr(word))
        if tok != word:
            raise FormatError(self.path, line, f"expected {word!r}, found {tok!r}")
        return line

    def number(self, what: str) -> float:
        tok, line = self.next(what)
        return _number(self.path, line, tok, what)


_TOKEN = re.compile(r"\S+")
MAX_NAME_WORDS = 64  # words of a joint name (names may contain spaces)
# frames x joints of a motion read: its rotations alone take 32 bytes each (1.6 GB here), 3.7 h
# of a 31-joint CMU skeleton at 120 fps; a file's rows must be there, so memory also stays
# within a few times the file's size
MAX_JOINT_FRAMES = 50_000_000
_VALUE_CHARS = 64  # characters a channel value and its spaces may take on a MOTION line
_LINE_BREAKS = re.compile("\r\n|[\n\r" + _ODD_BREAKS + "]")


def _numbered(lines: Iterable[str] | Iterable[tuple[int, str]]) -> Iterator[tuple[int, str]]:
    """(1-based line number, text) of ``lines`` (texts, or already numbered)."""
    for i, ln in enumerate(lines, 1):
        yield ln if isinstance(ln, tuple) else (i, ln)


def iter_lines(text: str) -> Iterator[str]:
    """``text.splitlines()`` one line at a time (a list of a large file's short lines takes
    25 times the text)."""
    pos = 0
    for m in _LINE_BREAKS.finditer(text):
        yield text[pos:m.start()]
        pos = m.end()
    if pos < len(text):
        yield text[pos:]


def check_size(path: Path, line: int | None, frames: int, joints: int) -> None:
    """Refuse a motion of more than :data:`MAX_JOINT_FRAMES` frames x joints."""
    if frames * joints > MAX_JOINT_FRAMES:
        raise FormatError(path, line, f"{frames:,} frames of {joints} joints, more than the "
                          f"{MAX_JOINT_FRAMES:,} frames x joints read at once: split the file")


def _number(path: Path, line: int, tok: str, what: str) -> float:
    try:
        value = float(tok)
    except ValueError:
        raise FormatError(path, line, f"expected a number for {what}, found {tok!r}") from None
    if not math.isfinite(value):
        raise FormatError(path, line, f"expected a finite number for {what}, found {tok!r}")
    if abs(value) > _MAX_ABS:
        raise FormatError(path, line, f"expected {what} below {_MAX_ABS:g} in size, found {tok}")
    return value


def _parse_hierarchy(tk: _Tokens) -> list[_Joint]:
    joints: list[_Joint] = []
    names: set[str] = set()
    tk.expect("HIERARCHY")
    tk.expect("ROOT")

    def open_joint(parent: int, keyword_line: int) -> None:
        words = tk.rest_of_line(keyword_line)
        brace_on_line = bool(words) and words[-1] == "{"
        if brace_on_line:
            words = words[:-1]
        if not words:
            raise FormatError(tk.path, keyword_line, "expected a joint name after ROOT/JOINT")
        name = " ".join(words)
        if name in names:
            raise FormatError(tk.path, keyword_line, f"joint name {name!r} is used twice")
        if len(joints) == MAX_JOINTS:
            raise FormatError(tk.path, keyword_line, f"more than {MAX_JOINTS} joints; expected "
                              "a body's rig")
        names.add(name)
        if not brace_on_line:
            tk.expect("{")
        j = _Joint(name, parent, keyword_line)
        seen_offset = False
        while tk.peek() in ("OFFSET", "CHANNELS"):
            tok, line = tk.next("OFFSET or CHANNELS")
            if tok == "OFFSET":
                j.offset = np.array([tk.number(f"{name} OFFSET {a}") for a in "xyz"])
                seen_offset = True
                continue
            count, line = tk.next("a channel count")
            if not (count.isascii() and count.isdigit() and len(count) == 1 and count <= "6"):
                raise FormatError(tk.path, line, f"expected a channel count from 0 to 6, "
                                  f"found {count[:40]!r}")
            for _ in range(int(count)):
                ch, line = tk.next(f"a channel name of {name!r}")
                if ch.lower() not in _CANON:
                    raise FormatError(tk.path, line, f"unknown channel {ch!r} on joint {name!r}; "
                                      f"expected one of {list(CHANNELS)}")
                if _CANON[ch.lower()] in j.channels:
                    raise FormatError(tk.path, line, f"channel {ch!r} repeats on joint {name!r}")
                j.channels.append(_CANON[ch.lower()])
        if not seen_offset:
            raise FormatError(tk.path, keyword_line, f"joint {name!r} has no OFFSET; expected "
                              "'OFFSET x y z' after its '{'")
        joints.append(j)

    open_joint(-1, tk.line)
    stack = [0]  # open joints; a loop, not recursion, so deep nesting cannot overflow the stack
    while stack:
        tok, line = tk.next("JOINT, End Site or '}'")
        if tok == "JOINT":
            if len(stack) == MAX_DEPTH:
                raise FormatError(tk.path, line, f"joints nested more than {MAX_DEPTH} deep; "
                                  "expected a body's rig")
            open_joint(stack[-1], line)
            stack.append(len(joints) - 1)
        elif tok == "End":
            tk.expect("Site")
            tk.expect("{")
            tk.expect("OFFSET")
            joints[stack[-1]].end_site = np.array(
                [tk.number(f"End Site {a}") for a in "xyz"])
            tk.expect("}")
        elif tok == "}":
            stack.pop()
        else:
            raise FormatError(tk.path, line, f"expected JOINT, End Site or '}}', found {tok!r}")
    if tk.peek() is not None:
        tok, line = tk.next("MOTION")
        raise FormatError(tk.path, line, f"expected MOTION after the ROOT joint, found {tok!r}")
    return joints


def _decode(path: Path) -> str:
    raw = path.read_bytes()
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        return raw.decode("latin-1")  # old exporters write joint names in Latin-1


def read_bvh(path: str | Path, unit: str = "auto", fold_static_root: bool = True,
             up: str = "auto", skip_frames: int = 0, root_offset: str = "auto") -> Motion:
    """Read a BVH file as a Motion in metres, Y up.

    Parameters
    ----------
    path : the .bvh file.
    unit : the file's length unit, one of ``m, cm, mm, in, cmu`` or ``auto`` (see the module).
    fold_static_root : fold the root into its single child with position channels when the
        root never moves or the child moves (see the module).
    up : the file's vertical axis, ``"y"``, ``"z"`` or ``"auto"`` (detected from the animated
        body, see :mod:`imuloco.io.upaxis`); Z-up files are turned Y up.
    skip_frames : leading frames to drop (the T-pose some converters prepend).
    root_offset : whether the root's position channels ``"replace"`` its OFFSET (the format's
        meaning, as Blender reads it) or are ``"add"``-ed to it (some iClone exports);
        ``"auto"`` adds it when that puts the body's lowest joint nearer the floor.

    Raises
    ------
    FormatError : naming the file, line and what was expected.
    """
    path = Path(path)
    if unit != "auto" and unit not in UNITS:
        raise ValueError(f"unit must be one of {sorted(UNITS)} or 'auto', got {unit!r}")
    up = check_up(up)
    if root_offset not in ("auto", "replace", "add"):
        raise ValueError(f"root_offset must be 'auto', 'replace' or 'add', got {root_offset!r}")
    joints, fps, data, extremes = _parse(path, _decode(path))
    check_skip(skip_frames, len(data), path)
    motion, scale = _build_motion(path, joints, data[skip_frames:], fps, UNITS.get(unit),
                                  fold_static_root, None if skip_frames else extremes)
    up = resolve_up(motion, up)
    motion = to_y_up(motion, up, path)
    # The root's OFFSET on the axes its position channels replace (see the module).
    shift = joints[0].offset * [f"{a}position" in joints[0].channels for a in "XYZ"] * scale
    shift = qrot(Z_TO_Y, shift) if up == "z" else shift
    if root_offset == "add" or (root_offset == "auto" and _offset_is_added(motion, shift)):
        motion.root += shift
    return motion


def parse_bvh(path: Path, text: str) -> tuple[list[_Joint], float, np.ndarray]:
    """The joints, frames per second and channel values (T, C) of a BVH ``text``.

    The MOTION block is read in one pass (:func:`imuloco.io.numtext.read_grid`); a block it
    does not take as a clean (T, C) array of finite numbers (and text with line breaks other
    than ``\n`` and ``\r\n``) goes to the line-by-line reading, which names the line and
    field at fault.
    """
    return _parse(path, text)[:3]


def _parse(path: Path, text: str
           ) -> tuple[list[_Joint], float, np.ndarray, tuple[np.ndarray, np.ndarray] | None]:
    """:func:`parse_bvh`, and each channel's highest and lowest value (C,) when the fast reading
    found them (for :func:`_build_motion`)."""
    m = None if _odd_breaks(text) else _motion_line(text)
    hierarchy = None if m is None else _memo_hierarchy(path, text[:m.start()])
    if hierarchy is not None:
        joints, motion_line = hierarchy
        parsed = _parse_motion_fast(path, text, m.end(), motion_line, joints)
        if parsed is not None:
            return joints, *parsed
    lines = enumerate(iter_lines(text), 1)  # read once, lazily: the hierarchy, then MOTION
    motion_at, last = None, 1

    def head() -> Iterator[tuple[int, str]]:
        nonlocal motion_at, last
        for i, ln in lines:
            last = i
            if ln.strip() == "MOTION":
                motion_at = i
                return
            yield i, ln

    joints = _parse_hierarchy(_Tokens(path, head()))  # says where MOTION was expected
    if motion_at is None:
        raise FormatError(path, last, "file ends early: expected a MOTION line after the "
                          "HIERARCHY")
    return joints, *_parse_motion(path, lines, motion_at, joints), None


_HIERARCHIES: dict[str, tuple[list[_Joint], int]] = {}


def _memo_hierarchy(path: Path, head: str) -> tuple[list[_Joint], int] | None:
    """The joints of the text ``head`` before a MOTION line, and that line's number; None when
    ``head`` itself has a MOTION line. Memoised by text (a folder's clips share one rig): the
    joints are shared, read only."""
    if head not in _HIERARCHIES:
        lines = head.splitlines()
        if any(ln.strip() == "MOTION" for ln in lines):
            return None
        if len(_HIERARCHIES) >= 64:
            _HIERARCHIES.clear()
        _HIERARCHIES[head] = _parse_hierarchy(_Tokens(path, lines)), len(lines) + 1
    return _HIERARCHIES[head]


def _motion_line(text: str) -> re.Match[str] | None:
    """``_MOTION.search(text)``, the first MOTION line, looked for where the word is (a
    regular expression tried at every line start costs more than the rest of the header)."""
    at = text.find("MOTION")
    while at >= 0:
        m = _MOTION.match(text, text.rfind("\n", 0, at) + 1)
        if m is not None:
            return m
        at = text.find("MOTION", at + 1)
    return None


def _odd_breaks(text: str) -> bool:
    """Whether ``text`` breaks lines other than by ``\\n`` or ``\\r\\n``."""
    if any(map(text.__contains__, _ODD_BREAKS[:5] if text.isascii() else _ODD_BREAKS)):
        return True
    return "\r" in text and text.count("\r") != text.count("\r\n")


def _parse_motion_fast(path: Path, text: str, start: int, motion_line: int,
                       joints: list[_Joint]
                       ) -> tuple[float, np.ndarray, tuple[np.ndarray, np.ndarray]] | None:
    """Frames per second, values (T, C) and each channel's highest and lowest value (C,) of the
    MOTION block after ``text[start]``, or None when the block needs the line-by-line reading
    (which then says what is wrong)."""
    h = _HEADERS.match(text, start)
    if h is None:
        return None
    frames_line = motion_line + text.count("\n", start, h.start(1))
    frames = _frame_count(path, frames_line, h.group(1))
    check_size(path, frames_line, frames, len(joints))
    fps = frame_rate(path, motion_line + text.count("\n", start, h.start(2)), h.group(2))
    width = _width(path, motion_line, joints)
    if len(text) - h.end() > frames * (width * _VALUE_CHARS + 2):
        return None  # more text than the values can take: the line reading says where
    data = read_grid(text, frames, width, start=h.end())
    if data is None:
        _check_frame_count(path, text, start, h.end(), motion_line, frames, width)
        return None
    high, low = data.max(axis=0), data.min(axis=0)
    if not (high.max() <= _MAX_ABS and low.min() >= -_MAX_ABS):
        return None  # NaN fails the comparisons too
    return fps, data, (high, low)


def _check_frame_count(path: Path, text: str, start: int, rows_at: int, motion_line: int,
                       frames: int, width: int) -> None:
    """Say it when the MOTION block from ``text[rows_at]`` is a clean grid of another count of
    rows than ``frames`` (as the line reading would, which took 17 s for 40,000 rows of 132
    channels)."""
    found = text.count("\n", rows_at) + (not text.endswith("\n"))
    if found == frames or found < 1 or read_grid(text, found, width, start=rows_at) is None:
        return
    first = motion_line + text.count("\n", start, rows_at)  # the first row's line
    if found < frames:
        raise FormatError(path, first + found - 1, f"truncated MOTION block: header says "
                          f"{frames} frames, found {found}")
    raise FormatError(path, first + frames, f"header says {frames} frames but the MOTION "
                      "block goes on")


def _frame_count(path: Path, line: int, token: str) -> int:
    digits = token.lstrip("0")
    if not (token.isascii() and token.isdigit() and 0 < len(digits) <= 8
            and int(digits) <= MAX_FRAMES):
        raise FormatError(path, line, f"expected a frame count from 1 to {MAX_FRAMES}, "
                          f"found {token[:40]!r}")
    return int(digits)


def _width(path: Path, motion_line: int, joints: list[_Joint]) -> int:
    """Channel values per frame."""
    width = sum(len(j.channels) for j in joints)
    if width == 0:
        raise FormatError(path, motion_line, "expected channels on at least one joint, "
                          "found none")
    return width


def _offset_is_added(motion: Motion, shift: np.ndarray) -> bool:
    """Whether adding the root's replaced OFFSET ``shift`` (3,) m, Y up, puts the body's lowest
    joint nearer the floor (height 0) over up to 64 frames than leaving it out does."""
    if abs(shift[1]) < 1e-6:
        return False
    idx, sk = spread_index(motion.num_frames, 64), motion.skeleton
    heights = joint_positions(motion.rotations[idx], motion.root[idx], sk.offsets, sk.parents,
                              list(range(sk.num_joints)))[..., 1]  # (T, J)
    lowest = float(median(heights.min(axis=1)))
    return abs(lowest + shift[1]) < abs(lowest)


_RATES: dict[str, float] = {}


def frame_rate(path: Path, line: int, token: str) -> float:
    """Frames per second of a ``Frame Time`` token, rounded to a whole number when the token is
    that rate's frame time printed to its decimals, to at least 3 significant digits
    (``0.016667`` is 60 fps, not 59.9988; ``0.03`` stays 33.33). Memoised by token (a
    folder's clips share one)."""
    if token not in _RATES:
        if len(_RATES) >= 256:
            _RATES.clear()
        _RATES[token] = _frame_rate(path, line, token)
    return _RATES[token]


def _frame_rate(path: Path, line: int, token: str) -> float:
    frame_time = _number(path, line, token, "Frame Time")
    if not 1.0 / MAX_FPS <= frame_time <= 1.0 / MIN_FPS:
        raise FormatError(path, line, f"expected a Frame Time from {1 / MAX_FPS:g} to "
                          f"{1 / MIN_FPS:g} s ({MIN_FPS:g} to {MAX_FPS:g} fps), found {token!r}")
    fps = 1.0 / frame_time
    whole = float(round(fps))
    try:
        exponent = decimal.Decimal(token).as_tuple().exponent
    except decimal.InvalidOperation:  # float() reads a few spellings Decimal does not
        exponent = 0
    half_ulp = 0.5 * 10.0 ** max(int(exponent), -300) if isinstance(exponent, int) else 0.0
    printed = abs(1.0 / max(whole, 1.0) - frame_time) <= half_ulp * (1 + 1e-9)
    if whole >= 1 and ((printed and half_ulp <= 2e-3 * frame_time) or abs(fps - whole) < 1e-3):
        return whole
    return fps


def _parse_motion(path: Path, lines: Iterator[tuple[int, str]], at: int, joints: list[_Joint]
                  ) -> tuple[float, np.ndarray]:
    """Frames per second and the channel values (T, C) of the MOTION block after line ``at``,
    from the numbered ``lines`` after it, line by line (the reference reading, which names the
    line at fault); values are kept as read, 8 bytes each (at most 4 times the text)."""
    body = ((i, ln) for i, ln in lines if ln.strip())  # the non-blank lines after MOTION
    last = at

    def header(key: str) -> tuple[str, int]:
        nonlocal last
        lineno, text = next(body, (None, ""))
        if lineno is None:
            raise FormatError(path, last, f"file ends early: expected a '{key}' line")
        last = lineno
        m = re.fullmatch(rf"\s*{key}\s*:\s*(\S+)\s*", text[:200])
        if m is None:
            raise FormatError(path, lineno, f"expected '{key}: <value>', found "
                              f"{text.strip()[:80]!r}")
        return m.group(1), lineno

    frames_s, frames_line = header("Frames")
    frames = _frame_count(path, frames_line, frames_s)
    check_size(path, frames_line, frames, len(joints))
    ft_s, ft_line = header("Frame Time")
    fps = frame_rate(path, ft_line, ft_s)
    width = _width(path, at, joints)
    values, count, last = array("d"), 0, ft_line
    for lineno, ln in body:
        if count == frames:
            raise FormatError(path, lineno, f"header says {frames} frames but the MOTION "
                              "block goes on")
        if len(ln) > _VALUE_CHARS * width:
            raise FormatError(path, lineno, f"a line of {len(ln):,} characters; expected "
                              f"{width} channel values (the HIERARCHY's channel count)")
        parts = ln.split()
        if len(parts) != width:
            raise FormatError(path, lineno, f"expected {width} channel values (the HIERARCHY's "
                              f"channel count), found {len(parts)}")
        try:
            row = np.array([float(p) for p in parts])
        except ValueError:
            col = next(c for c, p in enumerate(parts) if not _is_float(p))
            raise FormatError(path, lineno, f"expected a number for channel {col + 1} "
                              f"({_channel_name(joints, col)}), found {parts[col]!r}") from None
        bad = ~np.isfinite(row) | (np.abs(np.nan_to_num(row)) > _MAX_ABS)
        if bad.any():
            col = int(np.flatnonzero(bad)[0])
            raise FormatError(path, lineno, f"expected a finite number below {_MAX_ABS:g} in "
                              f"size for channel {col + 1} ({_channel_name(joints, col)}), "
                              f"found {parts[col]!r}")
        values.frombytes(row.tobytes())
        count, last = count + 1, lineno
    if count < frames:
        raise FormatError(path, last, f"truncated MOTION block: header says {frames} frames, "
                          f"found {count}")
    return fps, np.frombuffer(values, dtype=np.float64).reshape(frames, width).copy()


def _channel_name(joints: list[_Joint], col: int) -> str:
    for j in joints:
        if col < len(j.channels):
            return f"{j.name} {j.channels[col]}"
        col -= len(j.channels)
    return "?"


def _is_float(s: str) -> bool:
    try:
        float(s)
        return True
    except ValueError:
        return False


@dataclass(frozen=True)
class _Layout:
    """What a rig's HIERARCHY says about its channel columns, worked out once per rig (a
    folder's clips share one) so that each use is one array operation over frames and joints.

    pos_joint, pos_axis, pos_col : (P,) joint, axis (0-2) and column of each position channel.
    pos_slot : (P,) each position channel's joint's row in ``translating``.
    translating : the joints with position channels, ascending.
    by_order : (Euler order, joints (K,), columns (len(order), K)) of the rotation channels.
    unrotated : the joints without rotation channels.
    foldable : (J,) whether a joint has a single child, the next joint, with position channels.
    offsets : (J, 3) the OFFSET lines; names, parents (J,) as in the file.
    end_joints, end_sites : the joints with an End Site, and their offsets (E, 3).
    """

    pos_joint: np.ndarray
    pos_axis: np.ndarray
    pos_col: np.ndarray
    pos_slot: np.ndarray
    translating: list[int]
    by_order: list[tuple[str, np.ndarray, np.ndarray]]
    unrotated: np.ndarray
    foldable: list[bool]
    offsets: np.ndarray
    names: list[str]
    parents: np.ndarray
    end_joints: list[int]
    end_sites: np.ndarray


_LAYOUTS: dict[int, tuple[list[_Joint], _Layout]] = {}


def _layout(joints: list[_Joint]) -> _Layout:
    """The :class:`_Layout` of ``joints``, memoised by identity (the memoised hierarchies are
    shared, read only; an entry keeps its joints alive, so an id is never reused for it)."""
    hit = _LAYOUTS.get(id(joints))
    if hit is not None and hit[0] is joints:
        return hit[1]
    pos_joint, pos_axis, pos_col = [], [], []
    by_order: dict[str, tuple[list[int], list[list[int]]]] = {}
    col = 0
    for k, j in enumerate(joints):
        rot_cols, order = [], ""
        for i, c in enumerate(j.channels):
            if c.endswith("position"):
                pos_joint.append(k)
                pos_axis.append("XYZ".index(c[0]))
                pos_col.append(col + i)
            else:
                rot_cols.append(col + i)
                order += c[0]
        if order:
            ks, cols = by_order.setdefault(order, ([], []))
            ks.append(k)
            cols.append(rot_cols)
        col += len(j.channels)
    translating = sorted(set(pos_joint))
    parents = np.array([j.parent for j in joints], dtype=np.int64)
    rotated = {k for ks, _ in by_order.values() for k in ks}
    ends = [k for k, j in enumerate(joints) if j.end_site is not None]
    layout = _Layout(np.array(pos_joint, dtype=np.int64), np.array(pos_axis, dtype=np.int64),
                     np.array(pos_col, dtype=np.int64),
                     np.array([translating.index(k) for k in pos_joint], dtype=np.int64),
                     translating,
                     [(order, np.array(ks), np.array(cols).T) for order, (ks, cols)
                      in by_order.items()],
                     np.array([k for k in range(len(joints)) if k not in rotated], dtype=np.int64),
                     [np.count_nonzero(parents == k) == 1 and k + 1 in translating
                      for k in range(len(joints))],
                     np.array([j.offset for j in joints]).reshape(-1, 3),
                     [j.name for j in joints], parents,
                     ends, np.array([joints[k].end_site for k in ends]).reshape(-1, 3))
    if len(_LAYOUTS) >= 64:
        _LAYOUTS.clear()
    _LAYOUTS[id(joints)] = joints, layout
    return layout


def _span(index: np.ndarray) -> np.ndarray | slice:
    """``index`` (ascending) as a slice when it is a run of consecutive numbers: assigning
    through a slice costs less than through an index array."""
    if len(index) and index[-1] - index[0] == len(index) - 1:
        return slice(int(index[0]), int(index[-1]) + 1)
    return index


def _build_motion(path: Path, joints: list[_Joint], data: np.ndarray, fps: float,
                  scale: float | None, fold_static_root: bool,
                  extremes: tuple[np.ndarray, np.ndarray] | None = None
                  ) -> tuple[Motion, float]:
    """The Motion of channel values ``data`` (T, C), and the metres per file unit used
    (``extremes``: each channel's highest and lowest value, when known).

    Only what varies is computed per frame: rotations of joints whose angles never change are
    converted once, and positions per frame only for the root's chain (the folding); every other
    joint's position channels must be constant and become its offset."""
    t, n, lay = data.shape[0], len(joints), _layout(joints)
    high, low = extremes or (data.max(axis=0), data.min(axis=0))  # (C,) channel extremes
    offsets = lay.offsets.copy()  # (J, 3), position channels' first values
    offsets[lay.pos_joint, lay.pos_axis] = data[0, lay.pos_col]
    local_rot = np.empty((t, n, 4))
    if len(lay.unrotated):
        local_rot[:, lay.unrotated] = IDENTITY
    for order, ks, cols in lay.by_order:
        # from_euler's arithmetic on angles laid out (axis, ...) by one gather, its components
        # written straight into place; joints whose angles never change are converted once,
        # unless they are so few that converting them in every frame costs less than a call.
        still = (high[cols] == low[cols]).all(axis=0)  # (K,)
        if np.count_nonzero(still) * t < _CALL_ANGLES:
            still[:] = False
        for pick, angles in ((~still, lambda c: data[:, c].swapaxes(0, 1)),  # (3, T, K')
                             (still, lambda c: data[0, c])):  # (3, K'')
            if pick.any():
                half = angles(cols[:, pick]) * (np.pi / 360.0)
                parts = euler_components(np.sin(half), np.cos(half), order)
                where = _span(ks[pick])
                for k, part in enumerate(parts):
                    local_rot[:, where, k] = part

    def path_of(k: int) -> np.ndarray:
        """Joint ``k``'s position in its parent's frame in every frame, (T, 3)."""
        out = np.repeat(offsets[k][None], t, axis=0)
        mine = lay.pos_joint == k
        out[:, lay.pos_axis[mine]] = data[:, lay.pos_col[mine]]
        return out

    names, parents, translating = lay.names, lay.parents, lay.translating
    top, bottom = offsets[translating], offsets[translating]  # (K, 3) extremes over frames
    top[lay.pos_slot, lay.pos_axis] = high[lay.pos_col]
    bottom[lay.pos_slot, lay.pos_axis] = low[lay.pos_col]
    moving = dict(zip(translating, _moving(top, bottom)))
    first, root, root_rot = 0, path_of(0), local_rot[:, 0]
    while fold_static_root and first + 1 < n and lay.foldable[first]:
        # Fold the root into its single child when that child has position channels and
        # either it moves (its translation must be kept: "applied") or the root never moves
        # (a floor marker such as joint_Root); the child's world transform is the root's
        # transform applied to its own.
        child = first + 1
        if not (moving[child] or (np.ptp(root, axis=0).max() == 0.0
                                  and np.ptp(root_rot, axis=0).max() == 0.0)):
            break
        root = root + qrot(root_rot, path_of(child))
        root_rot = local_rot[:, child] = qmul(root_rot, local_rot[:, child])
        first = child
    for k in translating:
        if k > first and moving[k]:
            raise FormatError(path, joints[k].line, f"joint {names[k]!r} has moving position "
                              "channels below the root's chain of single children; expected "
                              "constant ones there (a Motion translates its root only)")

    offsets = offsets[first:]
    offsets[0] = 0.0
    sk_parents = np.where(parents[first:] >= 0, parents[first:] - first, -1)
    kept = tuple(names[first:])
    parts = cached_body_map(kept)
    if scale is None:
        scale = _memo_scale(kept, sk_parents.tobytes(), offsets.tobytes())
    sites = lay.end_sites * scale
    end_sites = {k - first: sites[i] for i, k in enumerate(lay.end_joints) if k >= first}
    try:
        skeleton = Skeleton(names[first:], sk_parents, offsets * scale, end_sites, dict(parts))
        motion = Motion(skeleton, local_rot[:, first:], root * scale, fps, path.stem)
    except ValueError as e:  # each value was checked finite and below 1e9: not expected
        raise FormatError(path, None, f"{e}; expected plausible values") from None
    return motion, scale


def _moving(high: np.ndarray, low: np.ndarray) -> np.ndarray:
    """Whether each joint's position, between ``high`` and ``low`` (K, 3) over the frames,
    varies by more than float noise: (K,)."""
    size = np.maximum(1.0, np.maximum(high, -low).max(axis=-1, initial=0.0))
    return (high - low).max(axis=-1, initial=0.0) > 1e-6 * size


@functools.lru_cache(maxsize=64)
def cached_body_map(names: tuple[str, ...]) -> dict[str, str]:
    """The body map of joint ``names`` (memoised: a folder's clips share one rig); callers
    copy it before handing it on."""
    return resolve_body_map(list(names), strict=False)


@functools.lru_cache(maxsize=256)
def _memo_scale(names: tuple[str, ...], parents: bytes, offsets: bytes) -> float:
    """:func:`_guess_scale` of a rig given as joint names, parents (int64 bytes) and offsets
    (float64 bytes), memoised: a folder's clips share their rig and often its offsets."""
    return _guess_scale(list(names), np.frombuffer(parents, dtype=np.int64),
                        np.frombuffer(offsets, dtype=np.float64).reshape(-1, 3),
                        cached_body_map(names))


def _guess_scale(names: list[str], parents: np.ndarray, offsets: np.ndarray,
                 parts: dict[str, str]) -> float:
    """Metres per file unit, from the leg length when the body map ``parts`` has hip and
    ankle."""
    for side in ("right", "left"):
        if f"{side}_hip" not in parts or f"{side}_ankle" not in parts:
            continue
        hip, j = names.index(parts[f"{side}_hip"]), names.index(parts[f"{side}_ankle"])
        bones = []
        while j > hip:
            bones.append(j)
            j = int(parents[j])
        leg = float(np.linalg.norm(offsets[bones], axis=-1).sum())
        if j == hip and leg > 0:
            if leg < 3:
                return UNITS["m"]
            return UNITS["cmu"] if leg < 30 else UNITS["cm"] if leg < 300 else UNITS["mm"]
    bones = sorted(np.linalg.norm(offsets[1:], axis=-1))[-4:]
    return UNITS["cm"] if sum(bones) > 3.0 else UNITS["m"]


def _decimals(unit_scale: float) -> int:
    """Decimals that resolve 1e-8 m in a unit of ``unit_scale`` metres (at least 6)."""
    return max(6, math.ceil(-math.log10(1e-8 / unit_scale) - 1e-9))


def write_bvh(motion: Motion, path: str | Path, unit: str = "cm", order: str = "ZXY",
              overwrite: bool = False, height: float | None = None) -> Path:
    """Write a Motion as BVH.

    The root gets 6 channels (position, then rotation), every other joint 3 rotation channels,
    in the intrinsic Euler ``order`` (a permutation of ``XYZ``); lengths are in ``unit``
    (``m, cm, mm, in, cmu``; Blender's importer takes the file's numbers as metres, so import
    a centimetre file with scale 0.01), angles in degrees with 6 decimals, lengths with enough
    decimals for 1e-8 m. Leaf joints get a non-zero End Site (:func:`end_sites`; ``height``:
    the body height in metres the head's top reaches at rest). Refuses to replace an existing
    file unless ``overwrite``. Returns the path.
    """
    return write_bvh_pieces([motion], motion.num_frames, path, unit, order, overwrite, height)


def write_bvh_pieces(pieces: Iterable[Motion], frames: int, path: str | Path, unit: str = "cm",
                     order: str = "ZXY", overwrite: bool = False,
                     height: float | None = None) -> Path:
    """Write consecutive Motions (one skeleton and frame rate, ``frames`` frames in all) as one
    BVH file, a piece at a time: a long reconstruction never needs to be in memory whole. See
    :func:`write_bvh` for the options; the file appears (atomically) only when complete."""
    path = Path(path)
    if unit not in UNITS:
        raise ValueError(f"unit must be one of {sorted(UNITS)}, got {unit!r}")
    order = order.upper()
    if sorted(order) != ["X", "Y", "Z"]:
        raise ValueError(f"order must be a permutation of 'XYZ' such as 'ZXY', got {order!r}")
    check_output(path, overwrite)
    k = 1.0 / UNITS[unit]
    dec = _decimals(UNITS[unit])
    written, dfs = 0, None
    with atomic_write(path, "w") as f:
        for motion in pieces:
            if written == 0:
                dfs = depth_first(motion.skeleton.parents)
                f.write("\n".join(_hierarchy(motion.skeleton, k, dec, order, height)) + "\n")
                f.write(f"MOTION\nFrames: {frames}\nFrame Time: {1.0 / motion.fps:.10g}\n")
            # the file's joints are in depth-first order, each its own rotation channels
            eul = to_euler(motion.rotations[:, dfs], order).reshape(motion.num_frames, -1)
            # one %-format a line (the same text as a format per value, a third of its time)
            line = " ".join([f"%.{dec}f"] * 3 + ["%.6f"] * eul.shape[1]) + "\n"
            rows = np.concatenate([motion.root * k, eul], axis=1).tolist()
            f.writelines(line % tuple(row) for row in rows)
            written += motion.num_frames
        if written != frames:
            raise ValueError(f"{path}: the pieces hold {written} frames, not {frames}")
    return path


# End Site lengths where a rig has none, as fractions of stature (Winter, Biomechanics and
# Motor Control of Human Movement, 4th ed., Fig. 4.1: head top above the skull base about
# 0.13 H, hand 0.108 H, toe tip beyond the ball of the foot about 0.04 H); the stature from
# the hip-to-ankle length, about 0.49 H there.
_END_SITE_STATURE = {"head": 0.13, "left_wrist": 0.108, "right_wrist": 0.108,
                     "left_toe": 0.04, "right_toe": 0.04}


def end_site(sk: Skeleton, j: int) -> np.ndarray:
    """The End Site offset (3,) in metres written for leaf joint ``j``: the rig's own, or where
    it has none (or one of zero length, which Blender drops with a warning) one along the
    joint's bone: of the body part's length (head top, hand, toes; see above) when the body map
    and the leg allow, else half the bone's length, at least 1 cm."""
    site = np.asarray(sk.end_sites.get(j, np.zeros(3)), dtype=np.float64)
    if np.linalg.norm(site) > 1e-6:
        return site
    bone = float(np.linalg.norm(sk.offsets[j]))
    direction = sk.offsets[j] / bone if bone > 1e-9 else np.array([0.0, 1.0, 0.0])
    length = max(0.5 * bone, 0.01)
    part = next((p for p, name in (sk.body_map or {}).items() if name == sk.names[j]), None)
    if part in _END_SITE_STATURE:
        try:
            length = _END_SITE_STATURE[part] * sk.leg_length() / 0.49
        except KeyError:  # no leg in the body map: keep the bone-based length
            pass
    return direction * length


def end_sites(sk: Skeleton, height: float | None = None, flat_toes: bool = False
              ) -> dict[int, np.ndarray]:
    """The End Site offsets (3,) in metres of every joint that gets one (each leaf, and any
    joint with the rig's own), by joint: :func:`end_site`'s, then

    - ``flat_toes``: a toe's (body map ``*_toe``) laid flat along the floor at rest, its
      length kept (the glTF writer's, whose mesh shows it);
    - ``height``: the head's, when the rig has none of its own and the head's End Site points
      up at rest (a T-pose rest, not the model rig's bones along +X), along the same direction
      to where the head's top is ``height`` above the rest figure's lowest joint or End Site
      (its feet on the floor): the figure at rest, as Blender shows it, is then as tall as the
      body it stands for (the stature rule above alone left it 0.2 % short on the sample's
      rig, and any rig whose head is not 0.13 of its stature further off).
    """
    ends = {j: end_site(sk, j) for j in range(sk.num_joints)
            if j in sk.end_sites or not sk.children(j)}
    part = {sk.names.index(n): p for p, n in (sk.body_map or {}).items()}
    if flat_toes:
        for j, e in ends.items():
            if part.get(j, "").endswith("_toe") and np.linalg.norm(e[[0, 2]]) > 1e-9:
                ends[j] = e * [1.0, 0.0, 1.0] * np.linalg.norm(e) / np.linalg.norm(e[[0, 2]])
    head = next((j for j in ends if part.get(j) == "head"), None)
    if height is None or head is None or np.linalg.norm(sk.end_sites.get(head, 0.0)) > 1e-6:
        return ends
    up = ends[head] / np.linalg.norm(ends[head])
    if up[1] < 0.5:  # not within 60 degrees of up at rest: no height to reach
        return ends
    _, rest = fk(np.broadcast_to(IDENTITY, (sk.num_joints, 4)), np.zeros(3), sk.offsets,
                 sk.parents)
    lowest = min(rest[:, 1].min(), *(rest[j, 1] + e[1] for j, e in ends.items() if j != head))
    ends[head] = up * max((lowest + height - rest[head, 1]) / up[1], 0.01)
    return ends


def check_joint_names(names: Iterable[str], where: str = "skeleton") -> None:
    """InputError naming the first joint name a BVH file cannot hold (empty, with blanks at an
    end, braces, tabs or line breaks): a rig's names are written back as they are, so a rig
    (``--skeleton``) is checked before the work rather than at writing."""
    for name in names:
        if not name.strip() or name != name.strip() or any(c in name for c in "{}\r\n\t"):
            raise InputError(f"{where}: joint name {excerpt(name)} cannot be written to BVH (no "
                             "braces, tabs, line breaks or blanks at its ends): rename it")


def _hierarchy(sk: Skeleton, k: float, dec: int, order: str, height: float | None = None
               ) -> list[str]:
    """The HIERARCHY section's lines of ``sk`` (lengths times ``k``, ``dec`` decimals; End
    Sites :func:`end_sites` reaching ``height``)."""
    check_joint_names(sk.names)
    ends = end_sites(sk, height)
    rot_channels = " ".join(f"{a}rotation" for a in order)
    out: list[str] = ["HIERARCHY"]

    def vec(v: np.ndarray) -> str:
        return " ".join(f"{x:.{dec}f}" for x in v)

    def close(j: int) -> None:
        pad = "\t" * len(open_)
        if j in ends:
            out.extend([f"{pad}\tEnd Site", f"{pad}\t{{",
                        f"{pad}\t\tOFFSET {vec(ends[j] * k)}", f"{pad}\t}}"])
        out.append(f"{pad}}}")

    open_: list[int] = []  # a loop, not recursion: a long chain cannot overflow the stack
    for j in depth_first(sk.parents):
        while open_ and open_[-1] != sk.parents[j]:
            close(open_.pop())
        pad = "\t" * len(open_)
        out.append(f"{pad}{'ROOT' if j == 0 else 'JOINT'} {sk.names[j]}")
        out.append(f"{pad}{{")
        out.append(f"{pad}\tOFFSET {vec(sk.offsets[j] * k)}")
        if j == 0:
            out.append(f"{pad}\tCHANNELS 6 Xposition Yposition Zposition {rot_channels}")
        else:
            out.append(f"{pad}\tCHANNELS 3 {rot_channels}")
        open_.append(int(j))
    while open_:
        close(open_.pop())
    return out


def depth_first(parents: np.ndarray) -> np.ndarray:
    """The joints in depth-first order, children in index order (the order of a BVH file's
    joints): (J,) joint indices. ``parents`` (J,), each before its children."""
    kids: list[list[int]] = [[] for _ in parents]
    for j in range(1, len(parents)):
        kids[int(parents[j])].append(j)
    out, stack = [], [0] if len(parents) else []
    while stack:
        j = stack.pop()
        out.append(j)
        stack.extend(reversed(kids[j]))
    return np.array(out, dtype=np.int64)
