"""The HTML viewer in a real headless browser: it loads offline, plays, pauses, scrubs, orbits.

Needs the ``selenium`` Python package (in the ``dev`` extra) and Debian's ``chromium`` and
``chromium-driver`` packages (``apt-get install -y chromium chromium-driver``); the tests skip
when either is missing, so CI machines without a browser still pass. Selenium is pointed at
the system chromedriver, so it downloads nothing.

Artefact: every run writes a screenshot of the playing viewer to pytest's ``tmp_path``; set
``IMULOCO_ARTIFACTS=DIR`` (for example ``tests/artifacts``) to also copy it to
``DIR/viewer.png`` for a person to look at.
"""

from __future__ import annotations

import os
import shutil
import time
from pathlib import Path

import pytest

pytest.importorskip("selenium.webdriver")  # the `browser` fixture (conftest) skips too


@pytest.fixture(scope="module")
def page(tmp_path_factory, sample_db) -> Path:
    from imuloco.viz.html import write_viewer

    clip = sample_db.where(content="walk", style="normal").clips[0].slice(0, 120)
    path = tmp_path_factory.mktemp("viewer") / "viewer.html"
    return write_viewer([clip, clip], path, ["ground truth", "reconstruction"])


def _wait(driver, script: str, timeout: float = 20.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        value = driver.execute_script(script)
        if value:
            return value
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for: {script}")


def _state(driver) -> dict:
    return driver.execute_script(
        "return {frame: imuloco.state.frame, playing: imuloco.state.playing, "
        "drawn: imuloco.state.framesDrawn, azimuth: imuloco.state.azimuth, "
        "joints: imuloco.screenJoints(0)};")


def _moved(a: list, b: list) -> float:
    return max(abs(p[0] - q[0]) + abs(p[1] - q[1]) for p, q in zip(a, b))


def test_viewer_plays_pauses_scrubs_and_orbits(browser, page, tmp_path):
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By

    browser.get(page.as_uri())
    _wait(browser, "return window.imuloco && imuloco.state.framesDrawn > 2")
    # it plays: the frame advances and the figure moves on screen
    a = _state(browser)
    _wait(browser, f"return imuloco.state.frame >= {a['frame']} + 5 || "
                   f"imuloco.state.frame < {a['frame']}")
    b = _state(browser)
    assert a["playing"] and b["drawn"] > a["drawn"]
    assert _moved(a["joints"], b["joints"]) > 3.0  # pixels
    # every joint is drawn inside the left panel of the canvas
    w, h = browser.execute_script("const c = document.getElementById('view'); "
                                  "return [c.width, c.height];")
    assert all(0 <= x <= w / 2 and 0 <= y <= h for x, y in b["joints"])

    shot = tmp_path / "viewer.png"
    browser.save_screenshot(str(shot))
    assert shot.stat().st_size > 5000
    if os.environ.get("IMULOCO_ARTIFACTS"):
        out = Path(os.environ["IMULOCO_ARTIFACTS"])
        out.mkdir(parents=True, exist_ok=True)
        shutil.copy(shot, out / "viewer.png")

    # pause: the frame stays
    browser.find_element(By.ID, "play").click()
    paused = _state(browser)
    time.sleep(0.3)
    assert not paused["playing"] and _state(browser)["frame"] == paused["frame"]
    # scrub to a frame: the slider drives the figure
    browser.execute_script("const s = document.getElementById('scrub'); s.value = 60; "
                           "s.dispatchEvent(new Event('input'));")
    s60 = _state(browser)
    assert s60["frame"] == 60
    browser.execute_script("const s = document.getElementById('scrub'); s.value = 75; "
                           "s.dispatchEvent(new Event('input'));")
    assert _moved(s60["joints"], _state(browser)["joints"]) > 3.0
    # orbit by dragging: same frame, another view
    before = _state(browser)
    canvas = browser.find_element(By.ID, "view")
    ActionChains(browser).move_to_element(canvas).click_and_hold().move_by_offset(
        120, 0).release().perform()
    after = _state(browser)
    assert after["frame"] == before["frame"]
    assert after["azimuth"] != pytest.approx(before["azimuth"])
    assert _moved(before["joints"], after["joints"]) > 3.0
    # speed
    browser.execute_script("const s = document.getElementById('speed'); s.value = '2'; "
                           "s.dispatchEvent(new Event('change'));")
    assert browser.execute_script("return imuloco.state.speed") == 2
    errors = [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]
    assert not errors, errors


def test_shared_projection_matches_the_python_renderer(browser, page):
    """StickFigure (shared with the live page) projects as imuloco.viz.skeleton.project."""
    import numpy as np

    from imuloco.viz.skeleton import project

    browser.get(page.as_uri())
    _wait(browser, "return window.imuloco && imuloco.state.framesDrawn > 0")
    pts = np.array([[0.0, 0.0, 0.0], [0.3, 1.7, -0.2], [-1.0, 0.5, 2.0]])
    az, el, zoom, height, floor, center = 2.1, 0.4, 1.5, 1.8, -0.05, [0.2, 9.0, -0.7]
    panel = {"x": 100, "width": 400, "height": 600}
    got = np.array(browser.execute_script(
        "const proj = StickFigure.projector(arguments[0], arguments[1]);"
        "return arguments[2].map(p => proj(...p));",
        {"azimuth": az, "elevation": el, "zoom": zoom, "height": height, "floor": floor,
         "center": center}, panel, pts.tolist()))
    scale = zoom * panel["height"] / (height * 1.5)
    screen = project(pts - [center[0], floor, center[2]], az, el) * scale
    expected = np.stack([300 + screen[:, 0], 0.82 * 600 - screen[:, 1]], axis=1)
    np.testing.assert_allclose(got, expected, atol=1e-9)


AMBER = (0xFF, 0xB0, 0x00)  # StickFigure.UNRELIABLE_COLOR


def _count_colour(driver, element: str, rgb: tuple[int, int, int]) -> int:
    return driver.execute_script("""
        const c = document.getElementById(arguments[0]);
        const px = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
        let n = 0;
        for (let i = 0; i < px.length; i += 4)
          if (px[i] === arguments[1] && px[i + 1] === arguments[2] && px[i + 2] === arguments[3])
            n++;
        return n;""", element, *rgb)


def test_viewer_shows_the_predicted_error_and_marks_unreliable_frames(browser, sample_db,
                                                                      tmp_path):
    import numpy as np

    from imuloco.viz.html import STICKFIGURE, UNRELIABLE_LABEL, write_viewer

    assert f'"{UNRELIABLE_LABEL}"' in STICKFIGURE.read_text()  # the page says what Python says
    clip = sample_db.where(content="walk", style="normal").clips[0].slice(0, 120)
    err = np.linspace(0.02, 0.08, 120)
    err[10] = np.nan  # a frame the method could not judge
    flags = np.zeros(120, bool)
    flags[40:60] = True
    page = write_viewer([clip, clip], tmp_path / "v.html", ["ground truth", "reconstruction"],
                        error_m=[None, err], unreliable=[None, flags])
    browser.get(page.as_uri())
    _wait(browser, "return window.imuloco && imuloco.state.framesDrawn > 1")
    browser.execute_script("imuloco.setPlaying(false); imuloco.seek(50);")
    c = browser.execute_script("return imuloco.confidence(1);")
    assert c["unreliable"] and c["errorM"] == pytest.approx(err[50], abs=1e-4)
    assert c["text"] == f"predicted error {100 * err[50]:.1f} cm \u00b7 {UNRELIABLE_LABEL}"
    line = browser.find_element("id", "confidence")
    assert UNRELIABLE_LABEL in line.text and "unreliable" in line.get_attribute("class")
    assert browser.execute_script("return imuloco.confidence(0).text;") == ""  # no data
    # the flagged figure is drawn over an amber halo, in its own (right) panel only
    w = browser.execute_script("return document.getElementById('view').width;")
    halo = browser.execute_script("""
        const c = document.getElementById('view'), w = c.width;
        const px = c.getContext('2d').getImageData(0, 0, w, c.height).data;
        let left = 0, right = 0;
        for (let i = 0; i < px.length; i += 4)
          if (px[i] === 255 && px[i + 1] === 176 && px[i + 2] === 0)
            ((i / 4) % w < w / 2) ? left++ : right++;
        return [left, right];""")
    assert halo[0] == 0 and halo[1] > 100, (halo, w)
    # a reliable frame: no halo, no label, its own predicted error
    browser.execute_script("imuloco.seek(90);")
    assert _count_colour(browser, "view", AMBER) == 0
    assert "unreliable" not in line.get_attribute("class")
    assert line.text == f"reconstruction: predicted error {100 * err[90]:.1f} cm"
    browser.execute_script("imuloco.seek(10);")
    assert line.text == "reconstruction: no prediction for this frame"  # NaN
    # the timeline strip: amber over the flagged sixth of its width; a click seeks
    assert browser.find_element("id", "confidence-bar").is_displayed()
    sw = browser.execute_script("return document.getElementById('strip').width;")
    amber = _count_colour(browser, "strip", AMBER)
    sh = browser.execute_script("return document.getElementById('strip').height;")
    assert amber == pytest.approx(sw * sh * 20 / 120, rel=0.15)
    from selenium.webdriver.common.action_chains import ActionChains

    strip = browser.find_element("id", "strip")
    ActionChains(browser).move_to_element_with_offset(strip, strip.size["width"] // 4, 0) \
        .click().perform()
    frame = browser.execute_script("return imuloco.state.frame;")
    assert abs(frame - 90) <= 2  # three quarters of 120 frames
    assert not [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]


def test_viewer_without_confidence_has_no_strip(browser, page):
    browser.get(page.as_uri())
    _wait(browser, "return window.imuloco && imuloco.state.framesDrawn > 1")
    assert not browser.find_element("id", "confidence-bar").is_displayed()
    assert browser.execute_script("return imuloco.confidence(1).text;") == ""
    assert _count_colour(browser, "view", AMBER) == 0
