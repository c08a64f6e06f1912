"""The README's walk-through, played on the bundled sample: a phone log (the demo's simulated
one), ``reconstruct`` to a BVH and a report with plots, ``render`` to the viewer, and the live
page over ``--https``'s self-signed certificate in headless Chromium. Everything stays on
loopback: the LAN address is printed, never connected to."""

from __future__ import annotations

import asyncio
import re
import shlex
import ssl
import urllib.request
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from imuloco.app.pipeline import DEMO_CLIP, DEMO_SEED, ModelChoice
from imuloco.cli import cli
from imuloco.io.sensorlog import write_generic_csv
from imuloco.sensors.simulate import simulate

README = Path(__file__).parents[1] / "README.md"


def readme_block(number: int) -> list[str]:
    """The commands after ``# N.`` in the README's code blocks, up to the block's end."""
    lines = README.read_text("utf-8").splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith(f"# {number}."))
    out = []
    for ln in lines[start + 1:]:
        if ln.startswith("```"):
            break
        if ln.strip() and not ln.startswith("#"):
            out.append(ln)
    return out


@pytest.fixture
def demo_log(sample_db, tmp_path, monkeypatch, ridge_without_demo_clip):
    """The demo's recording.csv (its clip, phone and seed) in ``tmp_path/demo_out``, the
    working directory; the model is ridge fitted without the demo clip (as a fallback is)."""
    from imuloco.app import pipeline

    clip = next(c for c in sample_db.clips if c.name == DEMO_CLIP)
    (tmp_path / "demo_out").mkdir()
    write_generic_csv(simulate(clip, ["right_ankle"], rate=100.0, noise="phone",
                               seed=DEMO_SEED), tmp_path / "demo_out" / "recording.csv")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(pipeline, "choose_model", lambda *a, **k: ModelChoice(
        ridge_without_demo_clip, "given", "ridge fitted without the demo clip"))
    return tmp_path


def test_readme_commands_write_a_bvh_a_report_with_plots_and_a_viewer(demo_log):
    pytest.importorskip("matplotlib")
    commands = readme_block(3)
    assert [c.split()[1] for c in commands] == ["reconstruct", "render", "live"]
    for command in commands[:2]:
        args = shlex.split(command)
        assert args[0] == "imuloco"
        result = CliRunner().invoke(cli, args[1:])
        assert result.exit_code == 0, result.output
    md = (demo_log / "walk.md").read_text()
    for kind in ("strides", "symmetry", "contacts"):
        png = demo_log / f"walk-{kind}.png"
        assert png.stat().st_size > 5000 and f"![{kind}](walk-{kind}.png)" in md
    assert png.read_bytes()[:4] == b"\x89PNG"
    # ridge predicts no error: no plot of it, and the summary says why
    assert not (demo_log / "walk-error.png").exists() and "gives no per-frame confidence" in md
    assert "## Read this first" in md and "A shin sensor's gait is the model's" in md
    assert "Gait note: model-derived" in md  # the shin's stride and speed have their note
    html = (demo_log / "walk.html").read_text()
    assert "<canvas" in html and (demo_log / "walk.bvh").read_text().startswith("HIERARCHY")


def test_live_https_prints_the_lan_address_a_qr_code_and_what_the_phone_asks(
        monkeypatch, ridge_without_demo_clip):
    """``live --host 0.0.0.0 --https``: the addresses name this machine's LAN address (the
    server itself is started on loopback here) and the phone's address is drawn as a QR."""
    pytest.importorskip("websockets")
    from imuloco.app import pipeline
    from imuloco.app.live import lan
    from imuloco.app.live import server as live_server

    async def on_loopback(server, host, port, ssl, replay, on_start):
        await server.start("127.0.0.1", 0, ssl)
        try:
            on_start(server)
        finally:
            await server.close()

    monkeypatch.setattr(live_server, "run", on_loopback)
    monkeypatch.setattr(live_server, "configure_logging", lambda: None)
    monkeypatch.setattr(pipeline, "choose_model", lambda *a, **k: ModelChoice(
        ridge_without_demo_clip, "given", "ridge"))
    result = CliRunner().invoke(cli, ["live", "--host", "0.0.0.0", "--https"])
    assert result.exit_code == 0, result.output
    phone = re.search(r"phone:\s+(\S+)", result.output).group(1)
    addresses = lan.lan_addresses()
    expected = addresses[0] if addresses else "localhost"
    assert phone.startswith(f"https://{expected}:") and "?token=" in phone
    print(f"phone address printed: {phone}")  # printed, not connected to
    assert "localhost" not in phone or not addresses
    assert "▀" in result.output or "█" in result.output  # the QR code's blocks
    assert "Advanced -> Proceed" in result.output and "Show Details" in result.output
    assert not lan.shown_host("127.0.0.1").startswith("127")


def test_lan_addresses_are_reachable_ones():
    import ipaddress

    pytest.importorskip("psutil")
    from imuloco.app.live import lan

    for a in lan.lan_addresses():
        ip = ipaddress.ip_address(a)
        assert ip.version == 4 and not ip.is_loopback and not ip.is_link_local


def test_self_signed_certificate_names_its_hosts(tmp_path):
    pytest.importorskip("cryptography")
    from cryptography import x509

    from imuloco.app.live import lan
    from imuloco.app.live.server import ssl_context

    cert, key = lan.self_signed(["192.168.1.20", "localhost"], tmp_path)
    c = x509.load_pem_x509_certificate(cert.read_bytes())
    alt = c.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert [str(ip) for ip in alt.get_values_for_type(x509.IPAddress)] == ["192.168.1.20"]
    assert alt.get_values_for_type(x509.DNSName) == ["localhost"]
    assert c.issuer == c.subject  # self-signed
    assert key.stat().st_mode & 0o077 == 0  # the key is the user's alone
    ssl_context(cert, key)  # loads as a server's TLS context


def test_live_page_over_https_shows_calibration_then_the_walker(browser, tmp_path, sample_db,
                                                                ridge_without_demo_clip,
                                                                wait_for, serve_threaded,
                                                                count_pixels_js):
    """The README's live command, on loopback: the page over the session's self-signed
    HTTPS is a secure context (phones give it their motion sensors), draws the calibration's
    progress while the phone stands still, then the replayed walker; the replay's end is
    logged for the terminal."""
    pytest.importorskip("websockets")
    from imuloco.app.live import lan
    from imuloco.app.live.server import ssl_context

    cert, key = lan.self_signed(["localhost", "127.0.0.1"], tmp_path)
    with serve_threaded(ridge_without_demo_clip, 4.0, ssl_context(cert, key)) as (server, loop):
        urls = server.urls("localhost")
        assert urls["live"].startswith("https://localhost:")
        # the certificate is the one served (Python's client trusts it when told to)
        ctx = ssl.create_default_context(cafile=str(cert))
        with urllib.request.urlopen(urls["phone"], context=ctx, timeout=10) as r:
            assert "devicemotion" in r.read().decode()
        browser.get(urls["live"])
        wait_for(lambda: browser.execute_script("return imuloco.state().skel !== null"))
        assert browser.execute_script("return window.isSecureContext") is True
        # a phone standing still for 2 s: the calibration screen, half full
        rows = np.zeros((200, 7))
        rows[:, 0] = np.arange(200) * 0.01
        rows[:, 2] = 9.81
        loop.call_soon_threadsafe(server.start_session)
        loop.call_soon_threadsafe(server.feed, rows)
        state = wait_for(lambda: browser.execute_script(
            "const s = imuloco.state(); return s.calibrating && s.calibrating.seconds > 1.9 "
            "? s.calibrating : null"))
        assert state["of"] == 4.0
        green = browser.execute_script(count_pixels_js + "return countPixels(0x44, 0xaa, 0x77);")
        assert green > 100  # the progress bar is drawn
        clip = next(c for c in sample_db.clips if c.name == DEMO_CLIP)
        path = write_generic_csv(simulate(clip, ["right_ankle"], 100.0, "phone", DEMO_SEED),
                                 tmp_path / "recording.csv")
        with pytest.MonkeyPatch.context() as mp:
            logged = []
            mp.setattr("imuloco.app.live.server.log.info",
                       lambda msg, *a: logged.append(msg % a))
            asyncio.run_coroutine_threadsafe(server.replay(path, speed=4.0), loop).result(90)
        wait_for(lambda: browser.execute_script("return imuloco.state().pose !== null"))
        assert browser.execute_script("return imuloco.state().calibrating") is None
        assert any(m.startswith("replay of recording.csv finished") for m in logged)
        assert not [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]
