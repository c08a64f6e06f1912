"""The load bench's reference parsers (timings not asserted)."""

from __future__ import annotations

from pathlib import Path

import pytest

import imuloco
from imuloco.errors import FormatError
from imuloco.lab.loadspeed import arrow_parse, numpy_parse

SAMPLE = Path(imuloco.__file__).parent / "data" / "sample"


def test_arrow_and_numpy_parse_count_the_same_frames(tmp_path):
    pytest.importorskip("pyarrow")
    files = sorted(SAMPLE.glob("*.bvh"))
    assert files
    for f in files:
        assert arrow_parse(f) == numpy_parse(f) > 0
    text = files[0].read_text(encoding="latin-1").rstrip("\n") + "\n1 2 3\n"
    bad = tmp_path / "short_row.bvh"
    bad.write_text(text, encoding="latin-1")
    with pytest.raises(FormatError, match="short_row.bvh"):
        arrow_parse(bad)


def test_reader_comparison_finds_the_largest_difference_and_refusals(tmp_path):
    from imuloco.io.bvh import read_bvh
    from imuloco.lab.loadspeed import compare_readers, motion_difference

    files = sorted(SAMPLE.glob("*.bvh"))[:2]
    assert compare_readers(files, read_bvh, progress=False) == (0.0, 0)

    def nudged(path):
        m = read_bvh(path)
        m.root[3, 1] += 0.25
        return m

    assert compare_readers(files, nudged, progress=False) == (0.25, 0)
    m = read_bvh(files[0])
    assert motion_difference(m, m.slice(0, 3)) == float("inf")  # other frames

    def refuses(path):
        raise FormatError(path, 1, "not today")

    assert compare_readers(files, refuses, progress=False) == (0.0, 2)
