"""The load bench's reference parsers (timings not asserted)."""

from __future__ import annotations

from pathlib import Path

import pytest

import imuloco
from imuloco.errors import FormatError
from imuloco.evaluate.loadspeed import arrow_parse, numpy_parse

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
