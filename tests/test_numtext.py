"""Whitespace-separated number grids: Arrow's reading and numpy's give the same numbers, and
the BVH reader builds the same Motion on either (no timings here: `imuloco bench --load`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_bvh import TWO_JOINT

from imuloco.data import SAMPLE_DIR
from imuloco.io import numtext
from imuloco.io.bvh import read_bvh
from imuloco.ops.rotations import from_euler

pytest.importorskip("pyarrow")


@pytest.fixture
def numpy_only(monkeypatch):
    """read_grid without pyarrow (numpy.loadtxt)."""
    monkeypatch.setattr(numtext, "_arrow", lambda: None)


def both(text: str, rows: int, width: int) -> tuple[np.ndarray | None, np.ndarray | None]:
    """read_grid's answer by Arrow alone (None for what it refuses), and by numpy alone."""
    pa, pc = numtext._arrow()
    try:
        arrow = numtext._arrow_grid(pa, pc, text, 0, rows, width)
    except pa.ArrowException:
        arrow = None
    saved = numtext._arrow
    numtext._arrow = lambda: None
    try:
        return arrow, numtext.read_grid(text, rows, width)
    finally:
        numtext._arrow = saved


@settings(max_examples=80, deadline=None)
@given(values=st.lists(st.floats(allow_nan=False, allow_infinity=False), min_size=6,
                       max_size=6),
       fmt=st.sampled_from(["{!r}", "{:.6f}", "{:.3e}", "{:g}", "{:+.2f}", "{:.17g}"]),
       sep=st.sampled_from([" ", "\t", "  ", " \t "]), crlf=st.booleans(),
       pad=st.sampled_from(["", " ", "\t"]), tail=st.sampled_from(["", "\n", "\n \n\n"]))
def test_arrow_and_numpy_read_the_same_numbers(values, fmt, sep, crlf, pad, tail):
    rows = [pad + sep.join(fmt.format(v) for v in values[i:i + 3]) + pad for i in (0, 3)]
    text = "\n".join(rows) + "\n" + tail
    text = text.replace("\n", "\r\n") if crlf else text
    arrow, numpy = both(text, 2, 3)
    assert arrow is not None and numpy is not None
    assert arrow.shape == (2, 3) and arrow.flags.writeable
    np.testing.assert_array_equal(arrow, numpy)
    np.testing.assert_array_equal(arrow.ravel(), [float(fmt.format(v)) for v in values])


@pytest.mark.parametrize("text, why", [
    ("1 2 3\n4 5\n", "a short row"),
    ("1 2 3\n4 5 6 7\n", "a long row"),
    ("1 2 3 4 5\n6\n", "the right count, wrong rows"),
    ("1 2 3\n4 5 6\n7 8 9\n", "a row too many"),
    ("1 2 3\n", "a row too few"),
    ("1 2 x\n4 5 6\n", "a word"),
    ("1 2 1_0\n4 5 6\n", "an underscore (Python's float takes it, numpy's parse does not)"),
    ("1 2 3,5\n4 5 6\n", "a decimal comma"),
    ("1 2\x013\n4 5 6\n", "a control character between numbers"),
    ("1 2 3\n4 5\n6\n", "the right count, a row broken in two"),
])
def test_grids_that_are_not_are_refused_by_both(text: str, why: str):
    arrow, numpy = both(text, 2, 3)
    assert arrow is None and numpy is None, why


@pytest.mark.parametrize("arrow", [True, False])
def test_a_grid_after_a_header_is_read_in_place(arrow: bool, monkeypatch):
    if not arrow:
        monkeypatch.setattr(numtext, "_arrow", lambda: None)
    head = "Frames: 2\nFrame Time: 0.01\n"
    got = numtext.read_grid(head + " 1 2.5 -3\n4 5e1 6\n\n", 2, 3, start=len(head))
    np.testing.assert_array_equal(got, [[1, 2.5, -3], [4, 50, 6]])
    assert numtext.read_grid(head + "1 2 3\n", 2, 3, start=len(head)) is None


def test_blank_lines_between_rows_are_left_to_numpy():
    text = "1 2 3\n\n4 5 6\n"
    assert numtext._arrow_grid(*numtext._arrow(), text, 0, 2, 3) is None
    np.testing.assert_array_equal(numtext.read_grid(text, 2, 3), [[1, 2, 3], [4, 5, 6]])


def test_non_finite_tokens_parse_for_the_caller_to_refuse():
    """Arrow reads "nan(1)", which Python's float refuses: the BVH reader's range check sends
    such blocks to the line-by-line reading, which names the field."""
    arrow, _ = both("1 2 nan(1)\n4 5 6\n", 2, 3)
    assert arrow is not None and np.isnan(arrow[0, 2])


def motions_equal(a, b) -> None:
    assert a.skeleton.names == b.skeleton.names and a.fps == b.fps and a.name == b.name
    np.testing.assert_array_equal(a.skeleton.parents, b.skeleton.parents)
    np.testing.assert_array_equal(a.skeleton.offsets, b.skeleton.offsets)
    assert a.skeleton.end_sites.keys() == b.skeleton.end_sites.keys()
    np.testing.assert_array_equal(a.rotations, b.rotations)
    np.testing.assert_array_equal(a.root, b.root)


def test_sample_reads_the_same_with_and_without_arrow(monkeypatch):
    files = sorted(SAMPLE_DIR.glob("*.bvh"))
    assert files
    arrow = [read_bvh(f) for f in files]
    monkeypatch.setattr(numtext, "_arrow", lambda: None)
    for f, m in zip(files, arrow):
        motions_equal(m, read_bvh(f))


@pytest.mark.shared
@pytest.mark.parametrize("folder, skip", [("bandai-namco-2", 0), ("bandai-namco-1", 0),
                                          ("cmu-iclone", 1)])
def test_shared_clips_read_the_same_with_and_without_arrow(shared_dir: Path, monkeypatch,
                                                           folder: str, skip: int):
    files = sorted((shared_dir.parent / folder).glob("*.bvh"))
    files = files[::max(1, len(files) // 4)]
    arrow = [read_bvh(f, skip_frames=skip) for f in files]
    monkeypatch.setattr(numtext, "_arrow", lambda: None)
    for f, m in zip(files, arrow):
        motions_equal(m, read_bvh(f, skip_frames=skip))


@pytest.mark.parametrize("once", [True, False])
def test_still_joints_are_converted_once_to_the_same_rotations(tmp_path: Path, monkeypatch,
                                                               once: bool):
    """A joint whose angles never change gets the rotation of its angles in every frame, as
    the per-frame conversion gives it (converted once, or with the others when few)."""
    from imuloco.io import bvh
    monkeypatch.setattr(bvh, "_CALL_ANGLES", 0 if once else 10**6)
    head = TWO_JOINT.split("MOTION")[0]  # root: 6 channels; child: Zrotation Xrotation Yrotation
    text = head + ("MOTION\nFrames: 3\nFrame Time: 0.0333333\n"
                   "0 0 0 10 20 30 12.5 -33.25 171.75\n"
                   "1 0 0 11 21 31 12.5 -33.25 171.75\n"
                   "2 0 0 12 22 32 12.5 -33.25 171.75\n")
    path = tmp_path / "still.bvh"
    path.write_text(text)
    m = read_bvh(path, unit="cm", up="y")
    want = from_euler(np.array([[10, 20, 30], [11, 21, 31], [12, 22, 32]], dtype=float), "ZXY")
    np.testing.assert_array_equal(m.rotations[:, 0], want)
    np.testing.assert_array_equal(m.rotations[:, 1],
                                  from_euler(np.tile([12.5, -33.25, 171.75], (3, 1)), "ZXY"))
