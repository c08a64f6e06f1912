"""Writing outputs so that a reader never sees half a file and no input is overwritten.

:func:`atomic_write` (a file object) and :func:`atomic_path` (a file name, for writers that
want one) write to a temporary file in the target's folder and rename it over the target only
when the writing succeeded (``os.replace`` is atomic on one file system), so an
interrupted run leaves the old file or none, never a truncated one. :func:`check_output`
refuses a target that exists (unless ``force``), that is one of the inputs, or whose folder
cannot be written.
"""

from __future__ import annotations

import errno
import os
import tempfile
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

from imuloco.errors import ImulocoError, OutputExistsError


def _read_umask() -> int:
    mask = os.umask(0o022)  # reading the mask sets it: done once, at import
    os.umask(mask)
    return mask


# mkstemp makes a file only its owner can read; a written output gets the permissions open()
# would give it (0o666 less the umask), so that others can read a shared study's outputs
_MODE = 0o666 & ~_read_umask()
# a write that fails for want of room (full disk, quota, file size limit) is the user's to fix:
# one line naming the file, not a traceback
FULL = {errno.ENOSPC, errno.EDQUOT, errno.EFBIG}


def check_output(path: str | Path, force: bool = False,
                 inputs: Iterable[str | Path] = ()) -> Path:
    """``path`` as a Path when it may be written: not an input, and new unless ``force``."""
    path = Path(path)
    resolved = path.resolve()
    for inp in inputs:
        if Path(inp).resolve() == resolved:
            raise ImulocoError(f"{path}: the output would overwrite an input; choose another "
                               "output path")
    if path.exists() and not force:
        raise OutputExistsError(f"{path} exists; pass --force to replace it")
    if path.parent.is_dir():  # fail now, not after the work: /proc, a read-only mount, ...
        try:
            tempfile.TemporaryFile(dir=path.parent).close()
        except OSError as e:
            raise ImulocoError(f"{path}: cannot write there ({e.strerror or e})") from None
    return path


def check_outputs(paths: Iterable[str | Path | None], force: bool = False,
                  inputs: Iterable[str | Path] = ()) -> list[Path]:
    """:func:`check_output` for several targets (``None`` skipped), naming every existing one
    in one error."""
    inputs = list(inputs)
    out = [check_output(p, True, inputs) for p in paths if p is not None]
    taken = [str(p) for p in out if p.exists()]
    if taken and not force:
        shown = ", ".join(taken[:5]) + (" ..." if len(taken) > 5 else "")
        raise OutputExistsError(f"{shown} exist{'s' if len(taken) == 1 else ''}; pass --force "
                                "to replace " + ("it" if len(taken) == 1 else "them"))
    return out


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary path beside ``path`` with its suffix (for writers that take a file name
    and pick the format from it: ffmpeg, matplotlib, imageio); renamed to ``path`` when the
    block succeeds, removed when it raises (``path`` is then left as it was)."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix, dir=path.parent)
    except OSError as e:  # a read-only or virtual file system (/proc), no permission, ...
        raise ImulocoError(f"{path}: cannot write there ({e.strerror or e})") from None
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, _MODE)
        os.replace(tmp, path)
    except OSError as e:
        Path(tmp).unlink(missing_ok=True)
        if e.errno in FULL:
            raise ImulocoError(f"{os.strerror(e.errno).lower()} writing {path}") from None
        raise
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


@contextmanager
def atomic_write(path: str | Path, mode: str = "wb", durable: bool = True) -> Iterator:
    """Open a temporary file beside ``path`` for writing; rename it to ``path`` on success.

    ``mode`` is ``"wb"`` or ``"w"`` (text, UTF-8). On an exception the temporary file is
    removed and ``path`` is left as it was. ``durable``: flush the file to disk before the
    rename (False for a cache, whose entries are checked when read and rebuilt if damaged:
    the flush was a third of the time of writing a cache entry)."""
    if mode not in ("wb", "w"):
        raise ValueError(f"atomic_write: mode must be 'wb' or 'w', not {mode!r}")
    with atomic_path(path) as tmp, open(tmp, mode, **({"encoding": "utf-8"} if mode == "w"
                                                      else {})) as f:
        yield f
        f.flush()
        if durable:
            os.fsync(f.fileno())


def atomic_write_text(path: str | Path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically, ending it with one newline: a report or
    table a script prints and keeps."""
    with atomic_write(path, "w") as f:
        f.write(text.rstrip("\n") + "\n")
