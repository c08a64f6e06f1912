"""The cache of parsed clips: same Motion back, keyed by content, reader and options; damaged
or foreign entries are never trusted; nothing is pickled."""

from __future__ import annotations

import json
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
    entries = list(cache_dir.glob("*.clip"))
    assert len(entries) == 1 and not list(cache_dir.glob("*.tmp"))
    head, payload = entries[0].read_bytes().split(b"\n", 1)  # JSON, then float64: no pickle
    assert json.loads(head)["names"] == first.skeleton.names
    assert len(payload) % 8 == 0 and first.rotations.tobytes() in payload

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
    assert b.num_frames == a.num_frames - 1 and len(list(cache_dir.glob("*.clip"))) == 2
    # edited file: another entry, and the edit shows
    clip.write_text(clip.read_text().replace("Frame Time:\t0.0333333", "Frame Time:\t0.04"))
    assert read_motion_cached(clip).fps == 25.0
    assert len(list(cache_dir.glob("*.clip"))) == 3
    # another reader version: nothing old is used
    monkeypatch.setattr(cache, "reader_version", lambda: "another reader")
    read_motion_cached(clip)
    assert len(list(cache_dir.glob("*.clip"))) == 4


def test_damaged_entry_is_read_again(cache_dir: Path, tmp_path: Path):
    clip = tmp_path / "c.bvh"
    clip.write_bytes(CLIP.read_bytes())
    good = read_motion_cached(clip)
    (entry,) = cache_dir.glob("*.clip")
    whole = entry.read_bytes()
    flipped = bytearray(whole)
    flipped[-5] ^= 1  # one bit of the root path: the CRC-32 differs
    head = json.loads(whole.split(b"\n", 1)[0])
    for damage in (b"", b"PK\x03\x04 not an entry", whole[:500], whole[:-8], whole + b"\0",
                   bytes(flipped), json.dumps({**head, "frames": -3}).encode() + b"\n",
                   json.dumps({**head, "end_sites": ["x"]}).encode() + whole.split(b"\n")[1],
                   b"[1, 2]\n" + whole):
        entry.write_bytes(damage)
        same(read_motion_cached(clip), good)
    # an entry holding a pickled object array is refused, not unpickled
    np.savez(entry.with_suffix(".npz"), names=np.array([object()], dtype=object))
    entry.with_suffix(".npz").replace(entry)
    same(read_motion_cached(clip), good)
    again = read_motion_cached(clip)  # rewritten whole, from the cache; writable like a read
    same(again, good)
    again.root += 1.0


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
    assert len(list(cache_dir.glob("*.clip"))) == 3
    again = load_database(SAMPLE_DIR, limit=3, progress=False)
    for a, b in zip(db.clips, again.clips):
        same(a, b)
