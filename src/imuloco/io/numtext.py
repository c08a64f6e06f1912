"""Whitespace-separated numbers as a (rows, width) float64 array, in one pass.

:func:`read_grid` uses pyarrow's compute kernels when pyarrow is installed (the ``dist`` extra)
and the text is ASCII, else ``numpy.loadtxt``. Both parse with correct rounding (Arrow's
``cast`` uses fast_float, numpy Python's own ``float`` parsing), so they give the same numbers;
Arrow's is the faster: on the shared BVH files it reads a MOTION block in about two thirds of
``numpy.loadtxt``'s CPU time, where pyarrow's CSV reader (one column per channel) and pandas'
are no faster than numpy, and splitting into Python strings costs as much as numpy's whole
parse (measured in the issue 22 work, see ``docs/results/io/README.md``).

Neither says what is wrong with text it refuses: callers read such text line by line.
"""

from __future__ import annotations

import functools
import io
import warnings
from types import ModuleType

import numpy as np


@functools.lru_cache(maxsize=1)
def _arrow() -> tuple[ModuleType, ModuleType] | None:
    """``pyarrow`` and its compute kernels, or None when pyarrow is not installed. (Kernels
    are called through ``pyarrow._compute.call_function``: ``pyarrow.compute`` and
    ``Array.to_numpy`` import pandas, which costs half a second.)"""
    try:
        import pyarrow
        import pyarrow._compute as kernels
    except ImportError:
        return None
    return pyarrow, kernels


def read_grid(text: str, rows: int, width: int) -> np.ndarray | None:
    """The numbers of ``text`` as a (``rows``, ``width``) array: ``rows`` lines that are not
    blank, each of ``width`` numbers separated by spaces or tabs (lines end in ``\n`` or
    ``\r\n``; no other line breaks). None when the text is not such a grid or a number does
    not parse; the numbers are not checked to be finite."""
    arrow, data = _arrow(), None
    if arrow is not None and text.isascii():
        try:
            data = _arrow_grid(*arrow, text, rows, width)
        except arrow[0].ArrowException:  # a token that is not a number, more than 2**31 tokens
            data = None
    if data is not None:
        return data
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # numpy warns of an empty text
        try:
            data = np.loadtxt(io.StringIO(text), dtype=np.float64, comments=None, ndmin=2)
        except (ValueError, Warning):
            return None
    return data if data.shape == (rows, width) else None


def _arrow_grid(pa: ModuleType, pc: ModuleType, text: str, rows: int, width: int
                ) -> np.ndarray | None:
    """:func:`read_grid` by Arrow kernels: lines, trimmed, split at whitespace (each line's
    count checked), the tokens cast to float64. None also for blank lines between rows (left
    to numpy); an ArrowException for a token that is not a number."""
    raw = text.encode("ascii")
    whole = pa.Array.from_buffers(pa.large_string(), 1, [
        None, pa.py_buffer(np.array([0, len(raw)], dtype=np.int64)), pa.py_buffer(raw)])
    lines = pc.call_function("list_flatten", [pc.call_function(
        "split_pattern", [whole], pc.SplitPatternOptions("\n"))])
    lines = pc.call_function("ascii_trim_whitespace", [lines])
    blank = _values(pc.call_function("binary_length", [lines])) == 0
    if len(blank) < rows or blank[:rows].any() or not blank[rows:].all():
        return None
    tokens = pc.call_function("ascii_split_whitespace", [lines])  # a blank line has one ""
    if not np.all(_values(pc.call_function("list_value_length", [tokens]))[:rows] == width):
        return None
    tokens = pc.call_function("list_flatten", [tokens]).slice(0, rows * width)
    numbers = pc.call_function("cast", [tokens], pc.CastOptions.safe(pa.float64()))
    return _values(numbers).reshape(rows, width)


def _values(array) -> np.ndarray:
    """A writable copy of the values of an Arrow numeric ``array`` without nulls
    (``to_numpy`` would import pandas)."""
    assert array.null_count == 0
    dtype = np.dtype(array.type.to_pandas_dtype())
    return np.frombuffer(array.buffers()[1], dtype=dtype, count=len(array),
                         offset=array.offset * dtype.itemsize).copy()
