"""A lock on an output folder, so that two runs never write one folder at once.

:class:`FolderLock` holds ``FOLDER/.imuloco.lock`` with ``fcntl.flock`` for the life of a run
and writes its holder in it (host, pid, start time, as JSON); a second run gets an
:class:`~imuloco.errors.ImulocoError` naming the holder. The kernel drops a flock when its
process dies (``kill -9`` too), and a run that ends removes the file: a lock file that is
there but not locked is a dead run's. It is taken over with a warning when its pid is dead on
this host; one naming another host, or a live pid here, is refused (its run may be alive:
remove the file by hand once it is not).

On a shared network file system: Linux emulates flock with the NFS lock protocol (NFSv4
locks, or lockd for v3), so runs on two machines exclude each other where the server
supports locking; where locks are local to each client (some SMB mounts with ``nobrl``, sshfs
and other FUSE file systems), the holder line still refuses a run while the file names
another host, but two runs started at the same instant on two machines can both get in.
(Hand-written: ``filelock`` and ``portalocker`` lock, but do not say who holds a lock nor
tell a dead holder's from a live one.)
"""

from __future__ import annotations

import fcntl
import json
import logging
import os
import socket
import time
from pathlib import Path
from typing import Self

from imuloco.errors import ImulocoError
from imuloco.io.atomic import pid_alive

log = logging.getLogger(__name__)
LOCK_NAME = ".imuloco.lock"


class FolderLock:
    """``with FolderLock(folder):`` one run at a time writes ``folder`` (see the module)."""

    def __init__(self, folder: str | Path) -> None:
        self.path = Path(folder) / LOCK_NAME
        self._fd: int | None = None

    def __enter__(self) -> Self:
        self.acquire()
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()

    def acquire(self) -> None:
        while True:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:  # BlockingIOError: another run holds it
                holder = _read(fd)
                os.close(fd)
                raise ImulocoError(f"{self.path.parent} is being written by another run "
                                   f"({_describe(holder)}; lock file {self.path}): wait for it "
                                   "to finish or choose another output folder") from None
            try:  # the file a finishing run removed meanwhile is not the lock: try again
                same = os.path.samestat(os.fstat(fd), os.stat(self.path))
            except FileNotFoundError:
                same = False
            if not same:
                os.close(fd)
                continue
            break
        holder = _read(fd)
        if holder:
            pid = holder.get("pid")
            dead = isinstance(pid, int) and pid > 0 and not pid_alive(pid)
            if holder.get("host") != socket.gethostname() or not dead:
                os.close(fd)
                raise ImulocoError(f"{self.path.parent} may be being written by another run "
                                   f"({_describe(holder)}): wait for it to finish, or remove "
                                   f"{self.path} if that run is gone")
            log.warning("%s: taking over the lock of a run that died (%s)", self.path.parent,
                        _describe(holder))
        os.ftruncate(fd, 0)
        os.pwrite(fd, json.dumps({"host": socket.gethostname(), "pid": os.getpid(),
                                  "started": time.strftime("%Y-%m-%dT%H:%M:%S%z")}).encode(), 0)
        self._fd = fd

    def release(self) -> None:
        if self._fd is not None:
            self.path.unlink(missing_ok=True)  # while locked: nobody reads a half-gone file
            os.close(self._fd)
            self._fd = None


def _read(fd: int) -> dict:
    """The holder a lock file names ({} when none or unreadable)."""
    try:
        data = json.loads(os.pread(fd, 4096, 0) or b"{}")
    except ValueError:
        return {"host": "?", "pid": 0}
    return data if isinstance(data, dict) else {"host": "?", "pid": 0}


def _describe(holder: dict) -> str:
    if not holder:
        return "holder unknown"
    return (f"host {holder.get('host', '?')}, pid {holder.get('pid', '?')}, started "
            f"{holder.get('started', '?')}")
