"""`imuloco render`'s videos: streamed frame by frame, a window, the GIF's cap, the legend and
the predicted-error strip (imuloco.viz.skeleton.render_videos, StickRenderer)."""

from __future__ import annotations

import logging
import tracemalloc
from typing import ClassVar

import numpy as np
import pytest
from click.testing import CliRunner

pytest.importorskip("matplotlib")
pytest.importorskip("imageio_ffmpeg")

import imuloco.viz.skeleton as sk
from imuloco.cli import cli
from imuloco.core.motion import Motion
from imuloco.errors import InputError
from imuloco.viz.skeleton import StickRenderer, frame_window, render_videos

SMALL = (160, 192)  # panel pixels: small frames keep the tests fast


@pytest.fixture(scope="module")
def walk(sample_db) -> Motion:
    """Four seconds of a bundled walk at 30 fps (121 frames)."""
    return sample_db.where(content="walk", style="normal").clips[0].slice(0, 121)


@pytest.fixture
def small_panels(monkeypatch):
    """Renderers draw :data:`SMALL` panels unless told otherwise."""
    original = StickRenderer.__init__

    def small(self, *args, **kwargs):
        kwargs.setdefault("panel_size", SMALL)
        original(self, *args, **kwargs)

    monkeypatch.setattr(StickRenderer, "__init__", small)


class FakeWriter:
    """Stands for :class:`VideoWriter`: records, at each frame it is sent, how many frames the
    renderer has drawn and whether the frame is the renderer's canvas (not a copy kept)."""

    log: ClassVar[list] = []

    def __init__(self, path, size, fps, overwrite=False, channels=3):
        self.path, self.fps, self.sent = path, fps, []
        FakeWriter.log.append(self)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def close(self):
        self.closed_at = FakeWriter.renderer.drawn

    def send(self, frame):
        renderer = FakeWriter.renderer
        canvas = np.asarray(renderer.canvas.buffer_rgba())
        self.sent.append((renderer.drawn, np.shares_memory(frame, canvas)))


def test_frames_go_to_the_encoders_one_at_a_time(tmp_path, walk, monkeypatch, small_panels):
    """Each frame is drawn, sent to every video that shows it and only then is the next one
    drawn: nothing holds more than the canvas, whatever the clip's length."""
    draw = StickRenderer.draw

    def counting(self, t):
        FakeWriter.renderer = self
        self.drawn = getattr(self, "drawn", 0) + 1
        return draw(self, t)

    monkeypatch.setattr(StickRenderer, "draw", counting)
    monkeypatch.setattr(sk, "VideoWriter", FakeWriter)
    FakeWriter.log = []
    render_videos([walk], [tmp_path / "a.mp4", tmp_path / "a.gif"], gif_max_seconds=1.0)
    mp4, gif = FakeWriter.log
    assert [n for n, _ in mp4.sent] == list(range(1, 122))  # frame k sent right after drawn
    assert [n for n, _ in gif.sent] == list(range(1, 31, 2))  # every other one, 1 s of them
    assert all(same for _, same in mp4.sent + gif.sent)  # the canvas itself, no copies
    assert mp4.fps == 30 and gif.fps == 15
    assert gif.closed_at == 29  # finished (its ffmpeg's frames let go) once its last was sent


def _peak_bytes(walk, path, end: float) -> int:
    """Python's peak traced bytes rendering an MP4 and a GIF of ``walk``'s first ``end`` s."""
    tracemalloc.start()
    try:
        render_videos([walk], [path.with_suffix(".mp4"), path.with_suffix(".gif")], end=end)
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_memory_does_not_grow_with_the_window(tmp_path, walk, small_panels):
    """The peak of Python's allocations (numpy's included) rendering 4 s is that of 0.5 s:
    the 105 frames more (123 KB each) are never held, not even for two videos at once."""
    short = _peak_bytes(walk, tmp_path / "s", 0.5)
    long = _peak_bytes(walk, tmp_path / "l", 4.0)
    frame = SMALL[0] * SMALL[1] * 4
    assert long < short + 2 * frame, (short, long)


def test_cli_window_selects_its_frames(tmp_path, walk):
    import imageio_ffmpeg

    from imuloco.io.bvh import write_bvh

    bvh = write_bvh(walk, tmp_path / "w.bvh")
    for args, frames in [(["--start", "2", "--end", "3"], 31), (["--start", "1.5"], 76),
                         (["--start", "1", "--seconds", "0.5"], 16), (["--end", "0.5"], 16)]:
        out = tmp_path / f"{len(args)}-{args[1]}.mp4"
        res = CliRunner().invoke(cli, ["render", str(bvh), "-o", str(out), *args])
        assert res.exit_code == 0, res.output
        assert imageio_ffmpeg.count_frames_and_secs(str(out))[0] == frames, args


@pytest.mark.parametrize(("start", "end", "message"), [
    (3.0, 2.0, "must come before end"), (2.0, 2.0, "must come before end"),
    (5.0, None, "start 5 s is outside"), (None, 4.5, "end 4.5 s is outside"),
    (-1.0, None, "outside"), (0.01, 0.02, "no frame"),
])
def test_bad_windows_are_refused(walk, start, end, message):
    with pytest.raises(InputError, match=message):
        frame_window(walk, start, end)


def test_cli_refuses_a_bad_window_before_writing(tmp_path, walk):
    from imuloco.io.bvh import write_bvh

    bvh = write_bvh(walk, tmp_path / "w.bvh")
    res = CliRunner().invoke(cli, ["render", str(bvh), "--out", str(tmp_path / "o"),
                                   "--start", "9"])
    assert res.exit_code == 1 and "Error: render window: start 9 s is outside" in res.output
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())


def test_a_window_is_all_the_motion_by_default(walk):
    assert frame_window(walk) == (0, 121)
    assert frame_window(walk, max_seconds=100) == (0, 121)  # --seconds is a cap, never an error
    assert frame_window(walk, 1.0, max_seconds=0.5) == (30, 46)


def test_gif_is_cut_with_a_message_and_the_mp4_is_not(tmp_path, walk, caplog, read_mp4,
                                                       small_panels):
    import imageio.v3 as iio

    with caplog.at_level(logging.WARNING, logger="imuloco.viz.skeleton"):
        mp4, gif = render_videos([walk], [tmp_path / "v.mp4", tmp_path / "v.gif"],
                                 start=1.0, gif_max_seconds=2.0)
    assert iio.imread(gif).shape[0] == 30  # 2 s at 15 fps from 1.0 s
    assert read_mp4(mp4, *SMALL).shape[0] == 91  # 1.0 s to the end, every frame
    assert "v.gif: a GIF shows at most 2 s: 1.0 to 3.0 s of the 1.0 to 4.0 s asked" in \
        caplog.text
    caplog.clear()
    render_videos([walk], [tmp_path / "short.gif"], end=1.0, gif_max_seconds=2.0)
    assert not caplog.records  # nothing cut, nothing said


def test_cli_out_writes_the_gif_unless_no_gif(tmp_path, walk):
    from imuloco.io.bvh import write_bvh

    bvh = write_bvh(walk.slice(0, 10), tmp_path / "w.bvh")
    res = CliRunner().invoke(cli, ["render", str(bvh), "--out", str(tmp_path / "r"),
                                   "--no-gif"])
    assert res.exit_code == 0, res.output
    assert sorted(p.name for p in (tmp_path / "r").iterdir()) == ["w.html", "w.mp4"]


def _strip_axes(renderer):
    return [ax for ax in renderer.figure.axes if ax not in renderer.axes]


def test_legend_and_error_strip_are_drawn(walk):
    err = np.linspace(0.05, 0.25, walk.num_frames)
    flags = np.zeros(walk.num_frames, bool)
    flags[40:60] = True
    r = StickRenderer([walk, walk], ["ground truth", "walk"], panel_size=SMALL,
                      error_m=[None, err], unreliable=[None, flags], window=(1.0, 3.0))
    (legend,) = r.figure.legends
    assert [t.get_text() for t in legend.get_texts()] == [
        "left side", "right side", "midline", "foot on the floor"]
    (strip,) = _strip_axes(r)
    (line,) = strip.get_lines()
    x, y = line.get_data()
    inside = (x >= 1.0) & (x <= 3.0)
    np.testing.assert_allclose(y[inside], 100 * err[np.round(x[inside] * 30).astype(int)])
    assert strip.get_xlim() == (1.0, 3.0)
    assert len(strip.collections) == 1  # the unreliable frames' shading
    label = " ".join(t.get_text() for t in strip.texts)
    assert label.startswith("walk: predicted error, cm") and "unreliable" in label

    # the cursor moves across the strip with the frame drawn
    def cursor_column(t):
        image = r.frame(t)
        x0, x1 = int(strip.bbox.x0) + 3, int(strip.bbox.x1)  # right of the axis line
        rows = slice(r.size[1] - int(strip.bbox.y1) + 2, r.size[1] - int(strip.bbox.y0) - 2)
        dark = (image[rows, x0:x1].astype(int).sum(axis=-1) < 120).sum(axis=0)
        return x0 + int(np.argmax(dark))

    a, b = cursor_column(45), cursor_column(75)
    assert b - a == pytest.approx(strip.bbox.width / 2, abs=2)  # 1.5 s and 2.5 s of 1-3 s


def test_no_strip_without_a_confidence_and_contacts_are_marked(walk):
    r = StickRenderer([walk], ["walk"], panel_size=SMALL)
    assert _strip_axes(r) == []
    _, down = r.contacts[0]
    assert down.shape == (walk.num_frames, 4) and 0.2 < down.mean() < 0.9
    t = int(np.flatnonzero(down.any(axis=1))[0])
    orange = np.all(np.abs(r.frame(t).astype(int) - [255, 127, 14]) < 40, axis=-1)
    assert orange[:-sk.LEGEND_PX].sum() > 5  # a dot at the foot, above the legend's own


def test_frames_do_not_depend_on_the_order_they_are_drawn_in(walk, monkeypatch):
    """The renderer prepares the geometry of several frames at once (sk.CHUNK_FRAMES): a
    frame drawn out of order, or again, is the same image."""
    monkeypatch.setattr(sk, "CHUNK_FRAMES", 16)
    r = StickRenderer([walk], ["walk"], panel_size=SMALL)
    times = range(0, 121, 7)
    forwards = [r.frame(t) for t in times]
    backwards = [r.frame(t) for t in reversed(times)][::-1]
    for a, b in zip(forwards, backwards):
        np.testing.assert_array_equal(a, b)
    assert len({a.tobytes() for a in forwards}) == len(forwards)  # the figure moves
