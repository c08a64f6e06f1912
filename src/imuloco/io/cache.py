"""A cache of parsed motion clips, so that a second bench or train on the same folders starts in
seconds.

Each entry is the Motion a reader returned, stored as one line of JSON (names, parents, sizes,
a CRC-32) and the arrays as raw little-endian float64 (a ``.clip`` file: nothing is pickled;
read in one pass into a writable buffer: loading takes about 40 % of the CPU time the
three-array ``.npz`` of format 1 took, whose zip members and headers cost more than the data),
named by the SHA-256 of the file's bytes, the reader's own source code (any change
to the readers invalidates every entry) and the reading options. Entries are written atomically
(:func:`imuloco.io.atomic.atomic_write`, not flushed to disk: the size and CRC-32 catch an
entry a crash left damaged); one that cannot be read is read again from the motion file and
rewritten.
The folder is ``$IMULOCO_CACHE``, else ``$XDG_CACHE_HOME/imuloco``, else ``~/.cache/imuloco``;
``IMULOCO_CACHE=off`` turns the cache off. A cache that cannot be written (a read-only home) is
skipped silently: it only saves time.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import zlib
from pathlib import Path

import numpy as np

from imuloco.core.motion import Motion
from imuloco.core.skeleton import Skeleton
from imuloco.errors import ImulocoError
from imuloco.io.asf_amc import find_asf
from imuloco.io.atomic import atomic_write
from imuloco.io.bvh import cached_body_map
from imuloco.io.motionfile import read_motion

# The code whose output an entry holds (paths in the package).
_SOURCES = ("io/bvh.py", "io/numtext.py", "io/asf_amc.py", "io/upaxis.py", "io/motionfile.py",
            "io/cache.py", "ops/rotations.py", "ops/kinematics.py")
_FORMAT = 2  # of the entry layout (see _store)
_MAX_HEAD = 1 << 24  # bytes of an entry's JSON line (names of 2,000 joints fit many times)


def cache_dir() -> Path | None:
    """The cache folder, or None when ``IMULOCO_CACHE=off``."""
    env = os.environ.get("IMULOCO_CACHE")
    if env is not None:
        return None if env.strip().lower() in ("off", "0", "") else Path(env).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "imuloco"


@functools.lru_cache(maxsize=1)
def reader_version() -> str:
    """SHA-256 of the readers' source code (and of numpy's major version, whose float parsing
    the reader relies on): entries of another reader are never used."""
    h = hashlib.sha256(f"format {_FORMAT}; numpy {np.__version__.split('.')[0]}".encode())
    package = Path(__file__).parents[1]
    for name in _SOURCES:
        h.update((package / name).read_bytes())
    return h.hexdigest()


def cache_key(data: bytes, options: dict) -> str:
    """The entry name of a motion file's bytes read with ``options``."""
    h = hashlib.sha256(data)
    h.update(reader_version().encode())
    h.update(json.dumps(options, sort_keys=True, default=str).encode())
    return h.hexdigest()


def read_motion_cached(path: str | Path, **options) -> Motion:
    """:func:`imuloco.io.motionfile.read_motion` through the cache (see the module).

    ``options`` are read_motion's (``up``, ``skip_frames``); the Motion's name is the file's
    stem, as the readers name it."""
    path = Path(path)
    folder = cache_dir()
    if folder is None:
        return read_motion(path, **options)
    # An AMC's skeleton is in its ASF: both files' bytes make the key.
    data = path.read_bytes()
    if path.suffix.lower() == ".amc":
        data += b"\0" + find_asf(path).read_bytes()
    entry = folder / (cache_key(data, options) + ".clip")
    motion = _load(entry, path.stem)
    if motion is None:
        motion = read_motion(path, **options)
        _store(entry, motion)
    return motion


def _load(entry: Path, name: str) -> Motion | None:
    """The Motion of an entry (see :func:`_store`), or None when there is none or it is
    damaged (then the motion file is read again)."""
    try:
        with open(entry, "rb") as f:
            head = json.loads(f.readline(_MAX_HEAD))
            names, parents, ends = head["names"], head["parents"], head["end_sites"]
            t, fps, j, e = head["frames"], float(head["fps"]), len(names), len(ends)
            if (head["format"] != _FORMAT or not all(isinstance(n, str) for n in names)
                    or not all(isinstance(k, int) and 0 <= k < j for k in ends)
                    or not isinstance(t, int) or t < 1):
                return None
            payload = bytearray(8 * (3 * j + 3 * e + 4 * j * t + 3 * t))
            if f.readinto(payload) != len(payload) or f.read(1) or (
                    zlib.crc32(payload) != head["crc32"]):
                return None
        floats = np.frombuffer(payload, dtype="<f8")  # writable: a bytearray's
        offsets, floats = floats[:3 * j].reshape(j, 3), floats[3 * j:]
        sites, floats = floats[:3 * e].reshape(e, 3), floats[3 * e:]
        rotations, root = floats[:4 * j * t].reshape(t, j, 4), floats[4 * j * t:].reshape(t, 3)
        skeleton = Skeleton(names, np.array(parents, dtype=np.int64), offsets,
                            dict(zip(ends, sites)), dict(cached_body_map(tuple(names))))
        return Motion(skeleton, rotations, root, fps, name)
    except FileNotFoundError:
        return None
    except (OSError, ValueError, KeyError, TypeError, OverflowError, MemoryError):
        return None  # damaged: read the motion file again


def _store(entry: Path, motion: Motion) -> None:
    """One line of JSON (format, joint names, parents, End Site joints, frames, fps and the
    CRC-32 of what follows), then the offsets, End Site offsets, rotations and root path as
    little-endian float64, flattened in that order."""
    sk = motion.skeleton
    ends = sorted(int(k) for k in sk.end_sites)
    payload = np.concatenate(
        [sk.offsets.ravel()] + [np.asarray(sk.end_sites[k], dtype=np.float64).ravel()
                                for k in ends]
        + [motion.rotations.ravel(), motion.root.ravel()]).astype("<f8").tobytes()
    head = {"format": _FORMAT, "names": list(sk.names), "parents": sk.parents.tolist(),
            "end_sites": ends, "frames": motion.num_frames, "fps": float(motion.fps),
            "crc32": zlib.crc32(payload)}
    try:
        with atomic_write(entry, durable=False) as f:  # a damaged entry is read again
            f.write(json.dumps(head).encode("ascii") + b"\n")  # ASCII: no raw line break
            f.write(payload)
    except (OSError, ImulocoError):  # atomic_write's "cannot write there"
        pass  # a cache that cannot be written only costs time
