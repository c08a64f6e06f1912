"""Videos streamed frame by frame to the encoder (imuloco.viz.skeleton.write_video)."""

from __future__ import annotations

import numpy as np
import pytest

from imuloco.viz.skeleton import write_video


def test_streamed_frames_are_all_written(tmp_path):
    """A generator of frames (a long recording's video never held in memory) gives as many
    frames as an array does."""
    import imageio_ffmpeg

    rng = np.random.default_rng(0)
    frames = rng.integers(0, 255, (7, 16, 24, 3), dtype=np.uint8)
    streamed = write_video((f for f in frames), tmp_path / "s.mp4", fps=10)
    stacked = write_video(frames, tmp_path / "a.mp4", fps=10)
    assert imageio_ffmpeg.count_frames_and_secs(str(streamed))[0] == 7
    assert imageio_ffmpeg.count_frames_and_secs(str(stacked))[0] == 7


def test_empty_stream_is_refused(tmp_path):
    with pytest.raises(ValueError, match="expected frames"):
        write_video(iter(()), tmp_path / "e.mp4", fps=10)
