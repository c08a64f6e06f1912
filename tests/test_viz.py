"""Stick-figure rendering, video files, the HTML viewer's page and the plots."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

pytest.importorskip("matplotlib")
pytest.importorskip("imageio_ffmpeg")

from imuloco.core.motion import Motion
from imuloco.viz.html import viewer_data, viewer_html, write_viewer
from imuloco.viz.skeleton import (
    LEGEND_PX,
    StickRenderer,
    camera_axes,
    frame_strip,
    joint_sides,
    project,
    render_video,
    write_video,
)


@pytest.fixture(scope="module")
def walk(sample_db) -> Motion:
    return sample_db.where(content="walk", style="normal").clips[0].slice(0, 45)


def test_camera_axes_are_orthonormal_and_right_handed():
    for az, el in [(0.0, 0.0), (1.0, 0.3), (-2.5, 1.2)]:
        r, u, c = camera_axes(az, el)
        m = np.stack([r, u, c])
        np.testing.assert_allclose(m @ m.T, np.eye(3), atol=1e-12)
        np.testing.assert_allclose(np.cross(r, u), c, atol=1e-12)  # right x up = to camera


def test_project_front_view_keeps_x_and_y():
    pts = np.array([[0.3, 1.2, -5.0], [-1.0, 0.0, 2.0]])
    np.testing.assert_allclose(project(pts, 0.0, 0.0), pts[:, :2])
    # a quarter turn of the camera about +Y sees world -Z on its right... and +X towards it
    np.testing.assert_allclose(project(np.array([0.0, 0.0, -1.0]), np.pi / 2, 0.0), [1.0, 0.0],
                               atol=1e-12)



def test_project_with_one_camera_per_frame_is_each_frame_projected_alone():
    """Azimuths (F,) project points (F, ..., 3) frame by frame, as F scalar calls do."""
    rng = np.random.default_rng(0)
    pts, az = rng.normal(size=(5, 4, 2, 3)), rng.uniform(-np.pi, np.pi, 5)
    one_each = np.stack([project(p, a, 0.3) for p, a in zip(pts, az)])
    np.testing.assert_allclose(project(pts, az, 0.3), one_each, atol=1e-12)
    assert camera_axes(az, 0.3)[0].shape == (5, 3)

def test_joint_sides_of_the_sample_skeleton(sample_db):
    sk = sample_db.skeleton
    sides = dict(zip(sk.names, joint_sides(sk)))
    assert sides["Hips"] == sides["Spine"] == sides["Head"] == "center"
    assert sides["Hand_L"] == sides["Toes_L"] == sides["Shoulder_L"] == "left"  # clavicle too
    assert sides["Hand_R"] == sides["Foot_R"] == sides["Shoulder_R"] == "right"


def test_renderer_draws_a_moving_figure(walk):
    r = StickRenderer([walk, walk], ["a", "b"], panel_size=(160, 192))
    a, b = r.frame(0), r.frame(20)
    assert a.shape == (192, 320, 3) and a.dtype == np.uint8
    # both panels draw the same motion: the same halves (below the titles and the clock,
    # above the legend's row across both) but for anti-aliasing at sub-pixel offsets
    assert np.mean(np.any(a[20:-LEGEND_PX, :160] != a[20:-LEGEND_PX, 160:], axis=-1)) < 0.02
    # the legs moved between the two frames
    assert np.count_nonzero(np.any(a != b, axis=-1)) > 100
    # the left side is drawn in blue, the right in red
    blue = np.all(np.abs(a.astype(int) - [31, 119, 180]) < 30, axis=-1)
    red = np.all(np.abs(a.astype(int) - [214, 39, 40]) < 30, axis=-1)
    assert blue.sum() > 20 and red.sum() > 20


@pytest.mark.parametrize("suffix", [".mp4", ".gif"])
def test_video_round_trip(tmp_path, suffix, read_mp4):
    import imageio.v3 as iio

    frames = np.full((6, 64, 96, 3), 255, dtype=np.uint8)
    for k in range(6):
        frames[k, 20:40, 10 + 10 * k: 20 + 10 * k] = (200, 30, 30)  # a square moving right
    path = write_video(frames, tmp_path / f"v{suffix}", fps=10)
    back = read_mp4(path, 96, 64) if suffix == ".mp4" else iio.imread(path)
    assert back.shape[0] == 6 and back.shape[1:3] == (64, 96)
    # the square is found where it was drawn
    for k in (0, 5):
        cols = np.flatnonzero((back[k, 30, :, 0].astype(int) - back[k, 30, :, 1]) > 80)
        assert 10 + 10 * k - 2 <= cols.min() and cols.max() <= 20 + 10 * k + 2
    with pytest.raises(FileExistsError):
        write_video(frames, path, fps=10)


def test_render_video_and_strip(tmp_path, walk):
    import imageio.v3 as iio

    gif = render_video([walk], tmp_path / "w.gif", max_seconds=0.5)
    assert iio.imread(gif).shape[0] == 8  # 0.5 s at 15 fps from 30 fps: frames 0, 2, .., 14
    png = frame_strip([walk], [0.0, 0.5, 1.0], tmp_path / "s.png", columns=2)
    img = iio.imread(png)
    assert img.shape[:2] == (2 * 384, 2 * 320)
    with pytest.raises(ValueError, match="mp4 or .gif"):
        write_video(np.zeros((1, 8, 8, 3), np.uint8), tmp_path / "x.avi", fps=1)


def test_viewer_page_is_offline_and_carries_the_motion(tmp_path, walk):
    path = write_viewer([walk, walk], tmp_path / "v.html", ["ground truth", "</script><b>x"])
    page = path.read_text()
    # nothing is fetched: no external scripts, styles or images
    assert not re.search(r"""(src|href)\s*=\s*["']?(https?:)?//""", page)
    assert "</script><b>" not in page  # the label cannot close the script element
    data = json.loads(re.search(r"const DATA = (\{.*?\});\n", page).group(1)
                      .replace("<\\/", "</"))
    assert data["frames"] == walk.num_frames and len(data["tracks"]) == 2
    pos = np.array(data["tracks"][0]["positions"]).reshape(walk.num_frames, -1, 3) / 1000
    np.testing.assert_allclose(pos, walk.positions(), atol=0.0006)  # rounded to mm
    assert data["parents"] == walk.skeleton.parents.tolist()
    with pytest.raises(FileExistsError):
        write_viewer([walk], path)


def test_viewer_page_inlines_the_shared_stick_figure_script(walk):
    from imuloco.viz.html import STICKFIGURE, STICKFIGURE_MARK

    page = viewer_html([walk, walk], ["a", "b"])
    js = STICKFIGURE.read_text()
    # the drawing code shared with the live page is in the file, before the code that uses it
    assert "const StickFigure" in js and page.count(js) == 1
    assert page.index("const StickFigure") < page.index("StickFigure.projector")
    assert "__IMULOCO_" not in page  # every placeholder filled
    # placeholders are filled once: a label that spells one comes through as it is
    data = re.search(r"const DATA = (\{.*?\});\n", viewer_html([walk], [STICKFIGURE_MARK]))
    assert json.loads(data.group(1))["tracks"][0]["label"] == STICKFIGURE_MARK


def test_viewer_rejects_other_skeletons(walk, two_joint_skeleton, spinning_motion):
    with pytest.raises(ValueError, match="topology"):
        viewer_data([walk, spinning_motion])
    assert "<title>" in viewer_html([walk], title="a & b") and "a &amp; b" in viewer_html(
        [walk], title="a & b")


def test_plots_write_pngs(tmp_path, walk, sample_db):
    import imageio.v3 as iio

    from imuloco.phases import gait_phases
    from imuloco.sensors.simulate import simulate
    from imuloco.viz.plots import plot_errors, plot_phases, plot_signals

    rec = simulate(walk, ["right_ankle", "pelvis"], noise="phone", seed=1)
    ph = gait_phases(walk)
    shifted = Motion(walk.skeleton, walk.rotations[::-1].copy(), walk.root, walk.fps, "rev")
    for path in (plot_signals(rec, tmp_path / "s.png", ph),
                 plot_phases(ph, tmp_path / "p.png"),
                 plot_errors(walk, shifted, tmp_path / "e.png")):
        img = iio.imread(path)
        assert img.ndim == 3 and img.shape[0] > 200 and img.std() > 5  # not blank
    with pytest.raises(FileExistsError):
        plot_phases(ph, tmp_path / "p.png")
