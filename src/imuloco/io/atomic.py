"""Writing outputs so that a reader never sees half a file and no input is overwritten.

:func:`atomic_write` (a file object) and :func:`atomic_path` (a file name, for writers that
want one) write to a temporary file in the target's folder and rename it over the target only
when the writing succeeded (``os.replace`` is atomic on one file system), so an
interrupted run leaves the old file or none, never a truncated one. :func:`check_output`
refuses a target that exists (unless ``force``), that is not a regular file (a FIFO, a device,
a symbolic link: never replaced, even with ``force``), that is one of the inputs, or whose folder
cannot be written; :func:`check_outputs` also refuses two outputs at one path.

Temporary files are named ``.NAME.imuloco-tmp-HOST-PID-RANDOM.SUFFIX`` (HOST a hash of the
host name): a run killed with ``kill -9`` leaves them, and :func:`clean_stale` (called by
:func:`check_output`) removes those of a process that is no longer alive on this host.
:class:`OutputSet` writes several files as one set: all to temporaries, then renamed together.
"""

from __future__ import annotations

import errno
import hashlib
import logging
import os
import re
import secrets
import socket
import stat
import tempfile
import time
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Self

from imuloco.errors import ImulocoError, OutputExistsError

log = logging.getLogger(__name__)


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


# a temporary file of ours: .NAME.imuloco-tmp-HOST-PID-RANDOM[.SUFFIX]
_TEMP = re.compile(r"^\.(?P<name>.+)\.imuloco-tmp-(?P<host>[0-9a-f]{8})-(?P<pid>\d+)-[0-9a-f]+")
HOST = hashlib.sha256(socket.gethostname().encode()).hexdigest()[:8]


def pid_alive(pid: int) -> bool:
    """Whether a process ``pid`` runs on this host (one of another user's counts)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def clean_stale(folder: str | Path, name: str | None = None, before: float | None = None
                ) -> list[Path]:
    """Remove the temporary files of ours in ``folder`` (of the output ``name``, or all) left by
    a process that died on this host (``kill -9``, a power cut) and last written before
    ``before`` (a time stamp; default now). Returns the files removed."""
    before = time.time() if before is None else before
    removed = []
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return removed
    for e in entries:
        m = _TEMP.match(e.name)
        if (m is None or (name is not None and m["name"] != name) or m["host"] != HOST
                or int(m["pid"]) == os.getpid() or pid_alive(int(m["pid"]))):
            continue
        try:
            if e.is_file(follow_symlinks=False) and e.stat().st_mtime < before:
                os.unlink(e.path)
                removed.append(Path(e.path))
        except OSError:  # gone meanwhile, or not ours to remove
            continue
    if removed:
        log.warning("removed %d temporary file(s) of an interrupted run in %s: %s",
                    len(removed), folder, ", ".join(p.name for p in removed[:3]))
    return removed


def _check_kind(path: Path) -> None:
    """Refuse an existing ``path`` that is not a regular file: a FIFO, a device, a folder or a
    symbolic link is never replaced (writing over ``/proc/self/fd/1``, a pipe another program
    reads or a link someone made is not what ``--force`` means)."""
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        return
    except OSError as e:
        raise ImulocoError(f"{path}: cannot write there ({e.strerror or e})") from None
    if not stat.S_ISREG(mode):
        kind = ("a symbolic link" if stat.S_ISLNK(mode) else "a folder" if stat.S_ISDIR(mode)
                else "a FIFO" if stat.S_ISFIFO(mode) else "a socket" if stat.S_ISSOCK(mode)
                else "a device" if stat.S_ISCHR(mode) or stat.S_ISBLK(mode) else "not a file")
        raise ImulocoError(f"{path} is {kind}, not a regular file; outputs only replace regular "
                           "files: choose another output path")


def check_output(path: str | Path, force: bool = False,
                 inputs: Iterable[str | Path] = ()) -> Path:
    """``path`` as a Path when it may be written: not an input, a regular file if it exists,
    and new unless ``force``. Removes stale temporary files of it (:func:`clean_stale`)."""
    path = Path(path)
    resolved = path.resolve()
    for inp in inputs:
        if Path(inp).resolve() == resolved:
            raise ImulocoError(f"{path}: the output would overwrite an input; choose another "
                               "output path")
    _check_kind(path)
    if path.exists() and not force:
        raise OutputExistsError(f"{path} exists; pass --force to replace it")
    if path.parent.is_dir():  # fail now, not after the work: /proc, a read-only mount, ...
        try:
            tempfile.TemporaryFile(dir=path.parent).close()
        except OSError as e:
            raise ImulocoError(f"{path}: cannot write there ({e.strerror or e})") from None
        if _TEMP.match(path.name) is None:  # not a staged temporary (OutputSet.path)
            clean_stale(path.parent, path.name)
    return path


def check_outputs(paths: Iterable[str | Path | None], force: bool = False,
                  inputs: Iterable[str | Path] = ()) -> list[Path]:
    """:func:`check_output` for several targets (``None`` skipped), naming every existing one
    in one error; two targets at one path (also through links or ``..``) are refused."""
    inputs = list(inputs)
    out = [check_output(p, True, inputs) for p in paths if p is not None]
    seen: dict[Path, Path] = {}
    for p in out:
        other = seen.setdefault(p.resolve(), p)
        if other is not p:
            raise ImulocoError(f"{other} and {p} are one file: give each output its own path")
    taken = [str(p) for p in out if p.exists()]
    if taken and not force:
        shown = ", ".join(taken[:5]) + (" ..." if len(taken) > 5 else "")
        raise OutputExistsError(f"{shown} exist{'s' if len(taken) == 1 else ''}; pass --force "
                                "to replace " + ("it" if len(taken) == 1 else "them"))
    return out


def _temporary(path: Path) -> Path:
    """A new empty temporary file beside ``path``, named as :data:`_TEMP` recognises."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(
            prefix=f".{path.name}.imuloco-tmp-{HOST}-{os.getpid()}-{secrets.token_hex(4)}",
            suffix=path.suffix, dir=path.parent)
    except OSError as e:  # a read-only or virtual file system (/proc), no permission, ...
        raise ImulocoError(f"{path}: cannot write there ({e.strerror or e})") from None
    os.close(fd)
    return Path(tmp)


def _commit(tmp: Path, path: Path) -> None:
    """Rename the written ``tmp`` to ``path`` (a regular file or none)."""
    os.chmod(tmp, _MODE)
    _check_kind(path)  # again: it may have appeared since the check before the work
    os.replace(tmp, path)


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary path beside ``path`` with its suffix (for writers that take a file name
    and pick the format from it: ffmpeg, matplotlib, imageio); renamed to ``path`` when the
    block succeeds, removed when it raises (``path`` is then left as it was)."""
    path = Path(path)
    tmp = _temporary(path)
    try:
        yield tmp
        _commit(tmp, path)
    except OSError as e:
        tmp.unlink(missing_ok=True)
        if e.errno in FULL:
            raise ImulocoError(f"{os.strerror(e.errno).lower()} writing {path}") from None
        raise
    except BaseException:
        tmp.unlink(missing_ok=True)
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


class OutputSet:
    """Several output files written as one set (a reconstruction's BVH, report, video ...).

    Each file is written to a temporary beside its target (:meth:`path`, :meth:`open`); when
    the block ends without an error all are renamed to their targets, in the order staged
    (stage the file that marks the set complete, e.g. a report, last); on an error none is.
    The renames are not one atomic step: a run killed between two leaves the earlier files
    new and the later ones old, so a set that must be detectably consistent names its other
    files' contents in its last file (:meth:`sha256` of a staged file, e.g. a report naming
    its BVH's hash), and a reader checks it (:func:`sha256_file`).

    >>> with OutputSet() as out:
    ...     write_bvh(motion, out.path(folder / "a.bvh"), overwrite=True)
    ...     with out.open(folder / "a.json", "w") as f:
    ...         f.write(json.dumps({"bvh_sha256": out.sha256(folder / "a.bvh")}))
    """

    def __init__(self) -> None:
        self._staged: dict[Path, Path] = {}  # target -> temporary

    def __enter__(self) -> Self:
        return self

    def path(self, target: str | Path) -> Path:
        """The temporary file (existing, empty; its target's suffix) that becomes ``target``."""
        target = Path(target)
        if target in self._staged:
            raise ValueError(f"{target} is staged twice in one output set")
        self._staged[target] = _temporary(target)
        return self._staged[target]

    @contextmanager
    def open(self, target: str | Path, mode: str = "wb") -> Iterator[IO]:
        """A file object (``"wb"`` or ``"w"``: UTF-8 text) writing ``target``'s temporary."""
        if mode not in ("wb", "w"):
            raise ValueError(f"OutputSet.open: mode must be 'wb' or 'w', not {mode!r}")
        with open(self.path(target), mode, **({"encoding": "utf-8"} if mode == "w" else {})) as f:
            yield f

    def sha256(self, target: str | Path) -> str:
        """The SHA-256 (hex) of what is staged for ``target`` so far."""
        return sha256_file(self._staged[Path(target)])

    def __exit__(self, kind: type[BaseException] | None, *exc: object) -> None:
        try:
            if kind is None:
                for tmp in self._staged.values():  # durable before any rename
                    fd = os.open(tmp, os.O_RDONLY)
                    try:
                        os.fsync(fd)
                    finally:
                        os.close(fd)
                for target, tmp in list(self._staged.items()):
                    _commit(tmp, target)
                    del self._staged[target]
        finally:
            for tmp in self._staged.values():
                tmp.unlink(missing_ok=True)
            self._staged.clear()


def sha256_file(path: str | Path) -> str:
    """The SHA-256 (hex) of a file's bytes, read in blocks."""
    with open(path, "rb") as f:
        return hashlib.file_digest(f, "sha256").hexdigest()
