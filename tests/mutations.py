"""Hypothesis strategies and checks shared by the readers' property tests."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
from hypothesis import strategies as st

from imuloco.errors import FormatError


@st.composite
def byte_mutations(draw, text: str) -> bytes:
    """Up to 6 random byte edits (flip, delete, insert, repeat, cut) of a valid file: inputs
    stay under a few kB."""
    b = bytearray(text.encode())
    for _ in range(draw(st.integers(1, 6))):
        i = draw(st.integers(0, len(b)))
        j = min(len(b), i + draw(st.integers(0, 24)))
        kind = draw(st.sampled_from(["flip", "delete", "insert", "repeat", "cut"]))
        if kind == "flip" and i < len(b):
            b[i] = draw(st.integers(0, 255))
        elif kind == "delete":
            del b[i:j]
        elif kind == "insert":
            b[i:i] = draw(st.binary(max_size=12))
        elif kind == "repeat":
            b[i:i] = b[i:j] * draw(st.integers(1, 20))
        else:
            del b[i:]
    return bytes(b)


def reads_cleanly(reader: Callable, path: Path):
    """``reader(path)``, which must either refuse the file with a FormatError naming it (then
    None) or return streams of finite times and values (then them)."""
    try:
        streams = reader(path)
    except FormatError as e:
        assert e.path == str(path)
        return None
    assert all(np.isfinite(s.times).all() and np.isfinite(s.values).all() for s in streams)
    return streams
