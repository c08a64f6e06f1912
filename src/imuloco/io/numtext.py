"""Whitespace-separated numbers as a (rows, width) float64 array, in one pass.

:func:`read_grid` uses pyarrow's compute kernels when pyarrow is installed (the ``dist`` extra)
and the text is ASCII, else ``numpy.loadtxt``. Both parse with correct rounding (Arrow's
``cast`` uses fast_float, numpy Python's own ``float`` parsing), so they give the same numbers;
Arrow's is the faster: on the shared BVH files it reads a MOTION block in about half of
``numpy.loadtxt``'s CPU time (numpy finds the tokens, Arrow trims and casts them; Arrow's own
split kernels cost as much again), where pyarrow's CSV reader (one column per channel) and
pandas' are no faster than numpy, and splitting into Python strings costs as much as numpy's
whole parse (measured in the issue 22 work, see ``docs/results/io/README.md``).

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
        import pyarrow  # the [dist] extra's, when installed
        import pyarrow._compute as kernels
    except ImportError:
        return None
    # a private module: should a pyarrow release move what is used here, numpy parses
    if not all(hasattr(kernels, n) for n in ("call_function", "SplitPatternOptions",
                                             "CastOptions")):
        return None
    return pyarrow, kernels


def read_grid(text: str, rows: int, width: int, start: int = 0) -> np.ndarray | None:
    """The numbers of ``text[start:]`` as a (``rows``, ``width``) array: ``rows`` lines that are
    not blank, each of ``width`` numbers separated by spaces or tabs (lines end in ``\n`` or
    ``\r\n``; no other line breaks). None when the text is not such a grid or a number does
    not parse; the numbers are not checked to be finite. (``start`` spares the caller a copy
    of the text after its header.)"""
    arrow, data = _arrow(), None
    if arrow is not None and not text.isascii():
        text, start = text[start:], 0
    if arrow is not None and text.isascii():
        try:
            data = _arrow_grid(*arrow, text, start, rows, width)
        except arrow[0].ArrowException:  # a token that is not a number, more than 2**31 tokens
            data = None
    if data is not None:
        return data
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # numpy warns of an empty text
        try:
            data = np.loadtxt(io.StringIO(text[start:]), dtype=np.float64, comments=None,
                              ndmin=2)
        except (ValueError, Warning):
            return None
    return data if data.shape == (rows, width) else None


def _arrow_grid(pa: ModuleType, pc: ModuleType, text: str, start: int, rows: int, width: int
                ) -> np.ndarray | None:
    """:func:`read_grid` by Arrow's cast: the tokens are found by numpy on the bytes (where a
    byte that is no space follows one that is), each line's count checked against the line
    breaks, and the text between one token's start and the next's handed to Arrow as a string
    array without copying, trimmed of its trailing whitespace and cast to float64. (Arrow's
    own split kernels cost twice the cast, building a list of strings per line.) None also
    for blank lines between rows (left to numpy) and control characters other than tab, CR
    and LF; an ArrowException for a token that is not a number."""
    raw = text.encode("ascii")
    byte = np.frombuffer(raw, dtype=np.uint8)[start:]
    space = byte <= 32  # tab, LF, CR and space: other control characters are refused here
    lf = np.count_nonzero(byte == 10)
    control = np.count_nonzero(byte < 32)
    if control != lf and control != (
            lf + np.count_nonzero(byte == 9) + np.count_nonzero(byte == 13)):
        return None
    # where each token begins, and after the last one where it ends: token i is the text from
    # bounds[i] to bounds[i + 1] (in byte, then in raw) less its trailing whitespace
    edge = np.flatnonzero(space[:-1] > space[1:])
    first = 0 if len(byte) and not space[0] else 1
    small = len(raw) < 2**31  # 32-bit offsets (Arrow's string rather than large_string)
    bounds = np.empty(len(edge) + 2 - first, dtype=np.int32 if small else np.int64)
    bounds[0] = 0
    np.add(edge, 1, out=bounds[1 - first:-1])
    end = len(byte)  # after the last token (bytes.rstrip would copy the text)
    while end and byte[end - 1] <= 32:
        end -= 1
    bounds[-1] = end
    starts = bounds[:-1]
    if len(starts) != rows * width or not _one_row_a_line(byte, starts, rows, width, lf):
        return None
    bounds += start
    tokens = pa.Array.from_buffers(pa.string() if small else pa.large_string(), len(starts), [
        None, pa.py_buffer(bounds), pa.py_buffer(raw)])
    tokens = pc.call_function("ascii_rtrim_whitespace", [tokens])
    numbers = pc.call_function("cast", [tokens], pc.CastOptions.safe(pa.float64()))
    return _values(numbers).reshape(rows, width)


def _one_row_a_line(byte: np.ndarray, starts: np.ndarray, rows: int, width: int, lf: int
                    ) -> bool:
    """Whether the tokens beginning at ``starts`` (``rows * width`` of them) of the text
    ``byte`` make ``rows`` lines of ``width`` tokens with no blank line between them (and only
    whitespace after them); ``lf``: the text's count of line feeds."""
    heads = starts[width::width]  # (rows - 1,) each later row's first token
    if (byte[heads - 1] == 10).all():  # right after a line break (no indent): the common case
        # and the other gaps between the rows' tokens hold no line break
        return lf - np.count_nonzero(byte[starts[-1]:] == 10) == rows - 1
    # tokens before each line break: (k + 1) * width before the k-th of the first rows - 1,
    # all of them from the last row's on
    before = np.searchsorted(starts, np.flatnonzero(byte == 10)[:rows])
    return (np.array_equal(before[:rows - 1], np.arange(width, rows * width, width))
            and (len(before) < rows or before[rows - 1] == len(starts)))


def _values(array) -> np.ndarray:
    """A writable copy of the values of an Arrow float64 ``array`` without nulls
    (``to_numpy`` would import pandas)."""
    assert array.null_count == 0 and array.type.bit_width == 64
    return np.frombuffer(array.buffers()[1], dtype=np.float64, count=len(array),
                         offset=array.offset * 8).copy()
