"""Shared fixtures: tiny generated skeletons and motions, the bundled sample, ../shared data."""

from __future__ import annotations

import asyncio
import contextlib
import shutil
import subprocess
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from imuloco.core.motion import Motion
from imuloco.core.skeleton import Skeleton
from imuloco.data import shared_data_dir
from imuloco.errors import FormatError
from imuloco.ops.rotations import about_y


@pytest.fixture(scope="session", autouse=True)
def _clip_cache(tmp_path_factory) -> None:
    """Parsed clips are cached in a temporary folder, never in the user's cache."""
    mp = pytest.MonkeyPatch()
    mp.setenv("IMULOCO_CACHE", str(tmp_path_factory.mktemp("imuloco-cache")))
    yield
    mp.undo()


@pytest.fixture(scope="session")
def real_dir() -> Path:
    """``../shared/data/real-imu`` (real IMUs with references); skipped when absent."""
    d = shared_data_dir()
    if d is None or not (d.parent / "real-imu").is_dir():
        pytest.skip("../shared/data/real-imu is absent")
    return d.parent / "real-imu"


@pytest.fixture(scope="session")
def shared_dir() -> Path:
    """``../shared/data/bandai-namco-2``; tests that use it are skipped when it is absent."""
    d = shared_data_dir()
    if d is None:
        pytest.skip("../shared data is absent")
    return d


@pytest.fixture(scope="session")
def sample_db():
    from imuloco.io.database import load_sample

    return load_sample()


@pytest.fixture
def two_joint_skeleton() -> Skeleton:
    """A root with one child 1 m above it along +Y."""
    return Skeleton(["root", "child"], np.array([-1, 0]), np.array([[0, 0, 0], [0, 1.0, 0]]))


@pytest.fixture
def spinning_motion(two_joint_skeleton: Skeleton) -> Motion:
    """The two-joint skeleton spinning about +Y at 1 rad/s for 3 s at 30 fps."""
    t = np.arange(90) / 30.0
    rot = np.zeros((90, 2, 4))
    rot[:, 0] = about_y(t)
    rot[:, 1, 3] = 1.0
    return Motion(two_joint_skeleton, rot, np.zeros((90, 3)), 30.0, "spin")


def read_mp4_frames(path: Path, width: int, height: int) -> np.ndarray:
    """Frames (N, height, width, 3) of an MP4 of that size, decoded by the bundled ffmpeg in
    one subprocess run (imageio's readers leave ffmpeg's pipes to the garbage collector:
    ResourceWarnings, errors here)."""
    import imageio_ffmpeg

    out = subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-v", "error", "-i", str(path),
                          "-f", "rawvideo", "-pix_fmt", "rgb24", "-"], capture_output=True,
                         check=True).stdout
    assert len(out) % (width * height * 3) == 0, "frame size differs"
    return np.frombuffer(out, np.uint8).reshape(-1, height, width, 3)


@pytest.fixture
def read_mp4():
    """:func:`read_mp4_frames`, for tests that check written videos."""
    return read_mp4_frames


def _reads_cleanly(reader: Callable, path: Path):
    """``reader(path)``, which must either refuse the file with a FormatError naming it (then
    None) or return streams of finite times and values (then them)."""
    try:
        streams = reader(path)
    except FormatError as e:
        assert e.path == str(path)
        return None
    assert all(np.isfinite(s.times).all() and np.isfinite(s.values).all() for s in streams)
    return streams


@pytest.fixture
def reads_cleanly():
    """:func:`_reads_cleanly`, the readers' property tests' verdict on a mutated input (the
    mutations: :mod:`imuloco.lab.mutations`)."""
    return _reads_cleanly


def _wait_for(check, timeout: float = 30.0):
    """``check()``'s first truthy value, polled every 50 ms; AssertionError after ``timeout``
    seconds."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        value = check()
        if value:
            return value
        time.sleep(0.05)
    raise AssertionError("timed out")


@pytest.fixture
def wait_for():
    """:func:`_wait_for`, for the browser tests that wait for a page's state."""
    return _wait_for


@contextlib.contextmanager
def _serve_threaded(method, calibrate_s: float, ssl_context=None):
    """A LiveServer of ``method`` listening on a free loopback port (over TLS with
    ``ssl_context``), its event loop in a thread: yields (server, loop)."""
    pytest.importorskip("websockets")
    from imuloco.app.live.server import LiveServer  # the [live] extra's

    loop = asyncio.new_event_loop()
    thread = threading.Thread(target=loop.run_forever, daemon=True)
    thread.start()
    server = LiveServer(method, calibrate_s=calibrate_s)
    asyncio.run_coroutine_threadsafe(server.start("127.0.0.1", 0, ssl_context), loop).result(20)
    try:
        yield server, loop
    finally:
        asyncio.run_coroutine_threadsafe(server.close(), loop).result(20)
        loop.call_soon_threadsafe(loop.stop)
        thread.join(20)
        loop.close()


@pytest.fixture
def serve_threaded():
    """:func:`_serve_threaded`, for the tests of the live pages in a browser."""
    return _serve_threaded


@contextlib.asynccontextmanager
async def _serve_loopback(method, **kwargs):
    """An async context: a LiveServer of ``method`` (no calibration; ``kwargs`` to it)
    listening on a free loopback port in the running event loop: yields (server, its ws://
    base address)."""
    from imuloco.app.live.server import LiveServer  # the [live] extra's

    server = LiveServer(method, calibrate_s=0, **kwargs)
    await server.start("127.0.0.1", 0)
    try:
        yield server, f"ws://127.0.0.1:{server.port}"
    finally:
        await server.close()


@pytest.fixture
def serve_loopback():
    """:func:`_serve_loopback`, for the tests of the live server's websockets."""
    pytest.importorskip("websockets")
    return _serve_loopback


async def _ws_closed(ws, timeout: float = 30) -> tuple[int, str]:
    """Code and reason the server closed the websocket ``ws`` with (reading what came
    before, each message within ``timeout`` seconds)."""
    from websockets.exceptions import ConnectionClosed  # the [live] extra's

    try:
        while True:
            await asyncio.wait_for(ws.recv(), timeout)
    except ConnectionClosed as e:
        return e.rcvd.code, e.rcvd.reason


@pytest.fixture
def ws_closed():
    """:func:`_ws_closed`."""
    return _ws_closed


# a page script's function: the live page drawn once, then its canvas's pixels of one colour
COUNT_PIXELS_JS = """
    function countPixels(r, g, b) {
      imuloco.draw();
      const c = document.getElementById('view');
      const px = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
      let n = 0;
      for (let i = 0; i < px.length; i += 4)
        if (px[i] === r && px[i + 1] === g && px[i + 2] === b) n++;
      return n;
    }
"""


@pytest.fixture
def count_pixels_js() -> str:
    """:data:`COUNT_PIXELS_JS`, to prepend to a script that calls ``countPixels(r, g, b)``."""
    return COUNT_PIXELS_JS


@pytest.fixture(scope="module")
def browser():
    """Debian's headless chromium driven by selenium through the system chromedriver (nothing
    is downloaded); skips when selenium, ``chromium`` or ``chromium-driver`` is missing."""
    webdriver = pytest.importorskip("selenium.webdriver")
    from selenium.webdriver.chrome.service import Service

    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    driver_path = shutil.which("chromedriver")
    if not (chromium and driver_path):
        pytest.skip("Debian chromium and chromium-driver are not installed")
    opts = webdriver.ChromeOptions()
    opts.binary_location = chromium
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                "--window-size=1000,700", "--disable-extensions", "--no-first-run"):
        opts.add_argument(arg)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    opts.accept_insecure_certs = True  # `live --https`'s self-signed certificate, on loopback
    driver = webdriver.Chrome(service=Service(driver_path), options=opts)
    driver.set_page_load_timeout(60)
    yield driver
    driver.quit()




@pytest.fixture(scope="session")
def ridge_without_demo_clip(sample_db):
    """ridge (online) fitted on the sample without the demo clip, as the pipeline's fallback."""
    from imuloco.app.pipeline import DEMO_CLIP
    from imuloco.methods import get_method

    keep = [i for i, lab in enumerate(sample_db.labels) if lab["name"] != DEMO_CLIP]
    return get_method("ridge").fit(sample_db.subset(keep), ["right_ankle"], "phone", 0)
