"""A cache of parsed motion clips, so that a second bench or train on the same folders starts in
seconds.

Each entry is the Motion a reader returned, stored as an ``.npz`` of plain arrays (names as a
unicode array; no object arrays, loaded with ``allow_pickle=False``), named by the SHA-256 of
the file's bytes, the reader's own source code (any change to the readers invalidates every
entry) and the reading options. Entries are written atomically
(:func:`imuloco.io.atomic.atomic_write`, not flushed to disk: zip's checksums catch an entry a
crash left damaged); one that cannot be read is read again from the motion file and rewritten.
The folder is ``$IMULOCO_CACHE``, else ``$XDG_CACHE_HOME/imuloco``, else ``~/.cache/imuloco``;
``IMULOCO_CACHE=off`` turns the cache off. A cache that cannot be written (a read-only home) is
skipped silently: it only saves time.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import zipfile
from pathlib import Path

import numpy as np

from imuloco.core.motion import Motion
from imuloco.core.skeleton import Skeleton
from imuloco.errors import ImulocoError
from imuloco.io.atomic import atomic_write
from imuloco.io.bvh import cached_body_map

# The code whose output an entry holds (paths in the package).
_SOURCES = ("io/bvh.py", "io/numtext.py", "io/asf_amc.py", "io/upaxis.py", "io/motionfile.py", "io/cache.py",
            "ops/rotations.py", "ops/kinematics.py")
_FORMAT = 1  # of the npz layout (see _store)


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
    from imuloco.io.motionfile import read_motion

    path = Path(path)
    folder = cache_dir()
    if folder is None:
        return read_motion(path, **options)
    # An AMC's skeleton is in its ASF: both files' bytes make the key.
    data = path.read_bytes()
    if path.suffix.lower() == ".amc":
        from imuloco.io.asf_amc import find_asf

        data += b"\0" + find_asf(path).read_bytes()
    entry = folder / (cache_key(data, options) + ".npz")
    motion = _load(entry, path.stem)
    if motion is None:
        motion = read_motion(path, **options)
        _store(entry, motion)
    return motion


def _load(entry: Path, name: str) -> Motion | None:
    try:
        # the file is opened here so that it is closed even when numpy cannot read it
        with open(entry, "rb") as fh, np.load(fh, allow_pickle=False) as z:
            names, ints, floats = [str(n) for n in z["names"]], z["ints"], z["floats"]
        j, e = len(names), len(ints) - len(names)  # joints, End Sites
        t, rest = divmod(len(floats) - 1 - 3 * j - 3 * e, 4 * j + 3)
        if rest or t < 1 or e < 0:
            return None
        fps, floats = float(floats[0]), floats[1:]
        offsets, floats = floats[:3 * j].reshape(j, 3), floats[3 * j:]
        ends, floats = floats[:3 * e].reshape(e, 3), floats[3 * e:]
        rotations, root = floats[:4 * j * t].reshape(t, j, 4), floats[4 * j * t:].reshape(t, 3)
        skeleton = Skeleton(names, ints[:j], offsets, dict(zip(ints[j:].tolist(), ends)),
                            dict(cached_body_map(tuple(names))))
        return Motion(skeleton, rotations, root, fps, name)
    except FileNotFoundError:
        return None
    except (OSError, ValueError, KeyError, TypeError, EOFError, zipfile.BadZipFile):
        return None  # damaged: read the motion file again


def _store(entry: Path, motion: Motion) -> None:
    """Three arrays: the joint names; parents then End Site joints (int64); fps, offsets, End
    Site offsets, rotations and root path (float64, flattened in that order)."""
    sk = motion.skeleton
    if any("\0" in n for n in sk.names):
        return  # numpy's unicode arrays drop trailing NULs: such names would not come back
    ends = sorted(sk.end_sites)
    floats = [np.array([motion.fps]), sk.offsets.ravel()]
    floats += [np.asarray(sk.end_sites[k], dtype=np.float64).ravel() for k in ends]
    floats += [motion.rotations.ravel(), motion.root.ravel()]
    try:
        with atomic_write(entry, durable=False) as f:  # a damaged entry is read again
            np.savez(f, names=np.array(sk.names, dtype=str),
                     ints=np.concatenate([sk.parents, np.array(ends, dtype=np.int64)]),
                     floats=np.concatenate(floats))
    except (OSError, ImulocoError):  # atomic_write's "cannot write there"
        pass  # a cache that cannot be written only costs time
