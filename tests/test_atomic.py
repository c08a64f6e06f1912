"""Atomic outputs: a failed write leaves the old file, an input is never a target."""

import pytest

from imuloco.errors import ImulocoError, OutputExistsError
from imuloco.io.atomic import atomic_write, atomic_write_text, check_output


def test_atomic_write_replaces_only_on_success(tmp_path):
    target = tmp_path / "out.txt"
    target.write_text("old")
    with pytest.raises(RuntimeError), atomic_write(target, "w") as f:
        f.write("half")
        raise RuntimeError("interrupted")
    assert target.read_text() == "old"
    assert list(tmp_path.iterdir()) == [target]  # no temporary file left
    with atomic_write(target, "w") as f:
        f.write("new")
    assert target.read_text() == "new"


def test_atomic_write_text_ends_with_one_newline(tmp_path):
    target = tmp_path / "table.md"
    target.write_text("old")
    atomic_write_text(target, "| a |\n| b |\n\n")
    assert target.read_text(encoding="utf-8") == "| a |\n| b |\n"
    atomic_write_text(target, "é")
    assert target.read_bytes() == "é\n".encode()
    assert list(tmp_path.iterdir()) == [target]


def test_check_output_refuses_existing_and_inputs(tmp_path):
    target = tmp_path / "x.csv"
    target.write_text("data")
    with pytest.raises(OutputExistsError, match="--force"):
        check_output(target)
    assert check_output(target, force=True) == target
    with pytest.raises(ImulocoError, match="overwrite an input"):
        check_output(tmp_path / "." / "x.csv", force=True, inputs=[target])


def test_an_interrupted_video_leaves_no_file(tmp_path):
    import numpy as np

    pytest.importorskip("imageio_ffmpeg")
    from imuloco.viz.skeleton import write_video

    def frames():
        for _ in range(3):
            yield np.zeros((16, 16, 3), np.uint8)
        raise KeyboardInterrupt  # the user stops a long encoding

    with pytest.raises(KeyboardInterrupt):
        write_video(frames(), tmp_path / "v.mp4", 10.0)
    assert list(tmp_path.iterdir()) == []
    path = write_video(np.zeros((4, 16, 16, 3), np.uint8), tmp_path / "v.mp4", 10.0)
    assert path.stat().st_size > 0 and list(tmp_path.iterdir()) == [path]


def test_check_outputs_names_every_existing_target(tmp_path):
    from imuloco.io.atomic import check_outputs

    a, b, c = (tmp_path / n for n in ("a.bvh", "b.html", "c.json"))
    a.write_text("x")
    b.write_text("y")
    with pytest.raises(OutputExistsError, match=r"a\.bvh, .*b\.html exist; pass --force"):
        check_outputs([a, None, b, c])
    assert check_outputs([a, None, b, c], force=True) == [a, b, c]


def test_atomic_write_gives_the_permissions_open_would(tmp_path):
    with open(tmp_path / "plain.txt", "w") as f:
        f.write("x")
    with atomic_write(tmp_path / "atomic.txt", "w") as f:
        f.write("x")
    modes = [(tmp_path / n).stat().st_mode & 0o777 for n in ("plain.txt", "atomic.txt")]
    assert modes[0] == modes[1]


def test_atomic_path_gives_the_permissions_open_would(tmp_path):
    from imuloco.io.atomic import atomic_path

    (tmp_path / "plain.png").write_bytes(b"x")
    with atomic_path(tmp_path / "atomic.png") as tmp:
        tmp.write_bytes(b"x")
    modes = [(tmp_path / n).stat().st_mode & 0o777 for n in ("plain.png", "atomic.png")]
    assert modes[0] == modes[1]


def test_outputs_are_flushed_to_disk_cache_entries_not(tmp_path, monkeypatch):
    """User outputs are fsync-ed before the rename; cache entries (checked when read) are not,
    and are still written whole, atomically."""
    import os

    from imuloco.io.cache import read_motion_cached

    synced = []
    monkeypatch.setattr(os, "fsync", lambda fd: synced.append(fd))
    with atomic_write(tmp_path / "out.txt", "w") as f:
        f.write("kept")
    assert len(synced) == 1
    monkeypatch.setenv("IMULOCO_CACHE", str(tmp_path / "cache"))
    from imuloco.data import SAMPLE_DIR

    clip = min(SAMPLE_DIR.glob("*.bvh"))
    first = read_motion_cached(clip)
    assert len(synced) == 1 and len(list((tmp_path / "cache").glob("*.clip"))) == 1
    again = read_motion_cached(clip)  # from the entry
    assert again.rotations.tobytes() == first.rotations.tobytes()
