"""Reading ``.npz`` files a user gives without trusting their headers.

numpy's ``np.load`` allocates the array a member's header declares before reading it: a file
of a few bytes declaring shape (1e6, 1e7) asks for 72.8 TiB. :func:`declared` reads a
member's header; :func:`load_npz` reads every member once its declared size fits the size the
zip declares for it (and :data:`MAX_MEMBER_BYTES`), never unpickling anything.
"""

from __future__ import annotations

import math
import zipfile
import zlib
from pathlib import Path
from typing import BinaryIO

import numpy as np

from imuloco.errors import FormatError

MAX_MEMBER_BYTES = 1 << 30  # one array once unzipped (a bench's per-frame rows: a few MB)


def declared(f: BinaryIO) -> tuple[tuple[int, ...], np.dtype, int]:
    """The shape, dtype and byte count the ``.npy`` header at ``f`` declares (``f`` is left
    after the header). ValueError for a header numpy does not read."""
    version = np.lib.format.read_magic(f)
    read = (np.lib.format.read_array_header_1_0 if version == (1, 0)
            else np.lib.format.read_array_header_2_0)
    shape, _, dtype = read(f)
    return shape, dtype, math.prod(shape) * dtype.itemsize


def load_npz(path: str | Path) -> dict[str, np.ndarray]:
    """The arrays of an ``.npz`` file by name, each checked before it is read: no object
    dtype, a declared size within what the zip holds for it. FormatError naming the file
    (and the array) otherwise, also for a damaged file."""
    path = Path(path)
    out = {}
    try:
        with zipfile.ZipFile(path) as zf:
            for info in zf.infolist():
                name = info.filename.removesuffix(".npy")
                if info.file_size > MAX_MEMBER_BYTES:
                    raise FormatError(path, None, f"array {name!r} unzips to "
                                      f"{info.file_size:,} bytes, more than the "
                                      f"{MAX_MEMBER_BYTES:,} allowed")
                with zf.open(info) as f:
                    shape, dtype, nbytes = declared(f)
                    if dtype.hasobject or nbytes > info.file_size:
                        raise FormatError(path, None, f"array {name!r} declares {dtype} of "
                                          f"shape {shape} ({nbytes:,} bytes) in "
                                          f"{info.file_size:,} bytes")
                with zf.open(info) as f:
                    out[name] = np.lib.format.read_array(f, allow_pickle=False)
    except (zipfile.BadZipFile, zlib.error, ValueError, OSError, EOFError,
            NotImplementedError) as e:
        if isinstance(e, (FormatError, FileNotFoundError)):
            raise
        raise FormatError(path, None, f"not an .npz file or corrupted ({type(e).__name__}: "
                                      f"{e})") from None
    return out
