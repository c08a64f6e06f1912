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


def test_force_replaces_only_regular_files(tmp_path):
    """A FIFO, a link (to /proc/self/fd/1, or to a file) and a device node are never replaced,
    even with --force (they were replaced by a regular file)."""
    import os

    fifo = tmp_path / "fifo.bvh"
    os.mkfifo(fifo)
    out = tmp_path / "stdout.bvh"
    out.symlink_to("/proc/self/fd/1")
    kept = tmp_path / "kept.txt"
    kept.write_text("kept")
    link = tmp_path / "link.txt"
    link.symlink_to(kept)
    for target, kind in ((fifo, "FIFO"), (out, "symbolic link"), (link, "symbolic link")):
        with pytest.raises(ImulocoError, match=f"is a {kind}, not a regular file"):
            check_output(target, force=True)
        with pytest.raises(ImulocoError, match="not a regular file"), \
                atomic_write(target, "w") as f:
            f.write("x")
    assert fifo.is_fifo() and out.is_symlink() and link.is_symlink()
    assert kept.read_text() == "kept"
    with pytest.raises(ImulocoError, match="/dev/null is a device"):
        check_output("/dev/null", force=True)  # checked only: never written in a test
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fifo.bvh", "kept.txt", "link.txt",
                                                           "stdout.bvh"]


def test_two_outputs_at_one_path_are_refused(tmp_path):
    """-o same.bvh --report same.bvh replaced the BVH with the JSON; also through .. and a
    linked folder."""
    from imuloco.io.atomic import check_outputs

    (tmp_path / "sub").mkdir()
    (tmp_path / "alias").symlink_to(tmp_path / "sub")
    a = tmp_path / "sub" / "a.bvh"
    for other in (a, tmp_path / "sub" / ".." / "sub" / "a.bvh", tmp_path / "alias" / "a.bvh"):
        with pytest.raises(ImulocoError, match="are one file"):
            check_outputs([a, tmp_path / "b.html", other], force=True)
    assert check_outputs([a, tmp_path / "a.json"]) == [a, tmp_path / "a.json"]


_KILLED_WRITE = """
import os, signal, sys
from imuloco.io.atomic import atomic_write
with atomic_write(sys.argv[1], "wb") as f:
    f.write(b"x" * 100_000)
    f.flush()
    os.kill(os.getpid(), signal.SIGKILL)
"""


def test_temporaries_of_a_killed_run_are_removed_by_the_next(tmp_path):
    """kill -9 during a write left a hidden temporary file (12-22 MB for a BVH) for ever; the
    next check of that output removes those of dead processes on this host, not others'."""
    import os
    import subprocess
    import sys

    target = tmp_path / "walk.bvh"
    proc = subprocess.Popen([sys.executable, "-c", _KILLED_WRITE, str(target)])
    assert proc.wait() == -9
    left = [p for p in tmp_path.iterdir()]
    assert len(left) == 1 and left[0].name.startswith(".walk.bvh.")
    alive = tmp_path / left[0].name.replace(f"-{proc.pid}-", f"-{os.getppid()}-")
    alive.write_bytes(b"a live run's")  # another run, still writing
    other = tmp_path / ".walk.bvh.notours.bvh"
    other.write_bytes(b"someone else's")
    past = os.stat(left[0]).st_mtime - 10
    for p in (left[0], alive):
        os.utime(p, (past, past))
    check_output(target)
    assert sorted(tmp_path.iterdir()) == sorted([alive, other])


_KILLED_SET = """
import os, signal, sys
from pathlib import Path
from imuloco.io import atomic
from imuloco.io.atomic import OutputSet
out = Path(sys.argv[1])
replace = os.replace
def replace_then_die(src, dst):
    replace(src, dst)
    if str(dst).endswith(".bvh"):
        os.kill(os.getpid(), signal.SIGKILL)
atomic.os.replace = replace_then_die
with OutputSet() as s:
    s.path(out / "a.bvh").write_text("new motion")
    with s.open(out / "a.json", "w") as f:
        f.write('{"bvh_sha256": "%s"}' % s.sha256(out / "a.bvh"))
"""


def test_an_output_set_is_renamed_together_and_detectably_consistent(tmp_path):
    """An OutputSet writes nothing when its block fails, all of its files when it succeeds;
    killed between two renames, its last file (the report) is the old one, whose hash of the
    BVH does not match the new BVH."""
    import json
    import subprocess
    import sys

    from imuloco.io.atomic import OutputSet, sha256_file

    (tmp_path / "a.bvh").write_text("old motion")
    with pytest.raises(RuntimeError), OutputSet() as s:
        s.path(tmp_path / "a.bvh").write_text("new motion")
        raise RuntimeError("interrupted")
    assert [p.name for p in tmp_path.iterdir()] == ["a.bvh"]
    with OutputSet() as s:
        s.path(tmp_path / "a.bvh").write_text("old motion 2")
        with s.open(tmp_path / "a.json", "w") as f:
            f.write(json.dumps({"bvh_sha256": s.sha256(tmp_path / "a.bvh")}))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.bvh", "a.json"]
    report = json.loads((tmp_path / "a.json").read_text())
    assert report["bvh_sha256"] == sha256_file(tmp_path / "a.bvh")
    proc = subprocess.run([sys.executable, "-c", _KILLED_SET, str(tmp_path)], check=False)
    assert proc.returncode == -9
    assert (tmp_path / "a.bvh").read_text() == "new motion"
    assert json.loads((tmp_path / "a.json").read_text())["bvh_sha256"] != sha256_file(
        tmp_path / "a.bvh")
    check_output(tmp_path / "a.json", force=True)  # the next run cleans the set's temporary
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.bvh", "a.json"]
