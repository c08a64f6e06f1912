"""The cache of parsed clips: same Motion back, keyed by content, reader and options; damaged
or foreign entries are never trusted; nothing is pickled."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from imuloco.data import SAMPLE_DIR
from imuloco.io import cache
from imuloco.io.bvh import read_bvh
from imuloco.io.cache import read_motion_cached

CLIP = SAMPLE_DIR / "dataset-2_walk_normal_001.bvh"


@pytest.fixture
def cache_dir(tmp_path: Path, monkeypatch) -> Path:
    d = tmp_path / "cache"
    monkeypatch.setenv("IMULOCO_CACHE", str(d))
    return d


def same(a, b) -> None:
    assert a.skeleton.names == b.skeleton.names and a.name == b.name and a.fps == b.fps
    np.testing.assert_array_equal(a.skeleton.parents, b.skeleton.parents)
    np.testing.assert_array_equal(a.skeleton.offsets, b.skeleton.offsets)
    assert a.skeleton.end_sites.keys() == b.skeleton.end_sites.keys()
    for k in a.skeleton.end_sites:
        np.testing.assert_array_equal(a.skeleton.end_sites[k], b.skeleton.end_sites[k])
    assert a.skeleton.body_map == b.skeleton.body_map
    np.testing.assert_array_equal(a.rotations, b.rotations)
    np.testing.assert_array_equal(a.root, b.root)


def test_second_read_comes_from_the_cache(cache_dir: Path, tmp_path: Path, monkeypatch):
    clip = tmp_path / CLIP.name
    clip.write_bytes(CLIP.read_bytes())
    first = read_motion_cached(clip)
    entries = list(cache_dir.glob("*.npz"))
    assert len(entries) == 1 and not list(cache_dir.glob("*.tmp"))
    with np.load(entries[0], allow_pickle=False) as z:  # plain arrays only
        assert all(z[k].dtype != object for k in z.files)

    def no_parsing(*a, **k):
        raise AssertionError("parsed again")

    monkeypatch.setattr("imuloco.io.motionfile.read_bvh", no_parsing)
    second = read_motion_cached(clip)
    same(first, second)
    same(first, read_bvh(clip))


def test_entries_follow_content_options_and_reader(cache_dir: Path, tmp_path: Path,
                                                   monkeypatch):
    clip = tmp_path / "c.bvh"
    clip.write_bytes(CLIP.read_bytes())
    a = read_motion_cached(clip)
    b = read_motion_cached(clip, skip_frames=1)  # other options: another entry
    assert b.num_frames == a.num_frames - 1 and len(list(cache_dir.glob("*.npz"))) == 2
    # edited file: another entry, and the edit shows
    clip.write_text(clip.read_text().replace("Frame Time:\t0.0333333", "Frame Time:\t0.04"))
    assert read_motion_cached(clip).fps == 25.0
    assert len(list(cache_dir.glob("*.npz"))) == 3
    # another reader version: nothing old is used
    monkeypatch.setattr(cache, "reader_version", lambda: "another reader")
    read_motion_cached(clip)
    assert len(list(cache_dir.glob("*.npz"))) == 4


def test_damaged_entry_is_read_again(cache_dir: Path, tmp_path: Path):
    clip = tmp_path / "c.bvh"
    clip.write_bytes(CLIP.read_bytes())
    good = read_motion_cached(clip)
    (entry,) = cache_dir.glob("*.npz")
    for damage in (b"", b"PK\x03\x04 not a zip", entry.read_bytes()[:500]):
        entry.write_bytes(damage)
        same(read_motion_cached(clip), good)
    # an entry holding a pickled object array is refused, not unpickled
    np.savez(entry, names=np.array([object()], dtype=object))
    same(read_motion_cached(clip), good)


def test_cache_off_and_unwritable(tmp_path: Path, monkeypatch):
    monkeypatch.setenv("IMULOCO_CACHE", "off")
    assert cache.cache_dir() is None
    same(read_motion_cached(CLIP), read_bvh(CLIP))
    blocker = tmp_path / "file"
    blocker.write_text("a file where the cache folder would be")
    monkeypatch.setenv("IMULOCO_CACHE", str(blocker / "cache"))
    same(read_motion_cached(CLIP), read_bvh(CLIP))  # no error: the cache only saves time


def test_default_cache_dir(monkeypatch, tmp_path: Path):
    monkeypatch.delenv("IMULOCO_CACHE")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert cache.cache_dir() == tmp_path / "imuloco"
    monkeypatch.delenv("XDG_CACHE_HOME")
    assert cache.cache_dir() == Path.home() / ".cache" / "imuloco"


def test_database_uses_the_cache(cache_dir: Path):
    from imuloco.io.database import load_database

    db = load_database(SAMPLE_DIR, limit=3, progress=False)
    assert len(list(cache_dir.glob("*.npz"))) == 3
    again = load_database(SAMPLE_DIR, limit=3, progress=False)
    for a, b in zip(db.clips, again.clips):
        same(a, b)
