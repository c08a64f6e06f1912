"""Live mode: causal resampling, calibration, streaming = offline, and the websocket server."""

from __future__ import annotations

import asyncio
import contextlib
import json
import urllib.error
import urllib.request

import numpy as np
import pytest

from imuloco.app.live.session import (
    KernelResampler,
    LiveSession,
    frames_to_json,
    kernel_resample,
    offline_frames,
)
from imuloco.core.recording import Recording
from imuloco.ops.rotations import from_rotvec, qrot
from imuloco.sensors.calibration import calibrate
from imuloco.sensors.simulate import simulate

CLIP = "dataset-2_walk_normal_001"
CALIB_S = 4.0


@pytest.fixture(scope="module")
def fitted(ridge_without_demo_clip):
    """ridge (online) fitted on the sample without the streamed clip."""
    return ridge_without_demo_clip


@pytest.fixture(scope="module")
def phone(sample_db):
    """A simulated phone on the right shank, strapped turned by an arbitrary rotation:
    times (N,), acc and gyro (N, 1, 3) in the phone's axes."""
    clip = next(c for c in sample_db.clips if c.name == CLIP)
    rec = simulate(clip, ["right_ankle"], rate=100.0, noise="phone", seed=11)
    q = from_rotvec(np.array([0.4, -1.2, 2.0]))
    return rec.times, qrot(q, rec.acc), qrot(q, rec.gyro)


def _irregular(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.cumsum(rng.uniform(0.004, 0.016, n))


def test_online_resampler_gives_the_batch_frames_one_period_late():
    t = _irregular(400, 0)
    x = np.random.default_rng(1).normal(size=(400, 3))
    r = KernelResampler(30.0)
    got = []
    for ti, xi in zip(t, x):
        for k, tk, v in r.push(ti, xi):
            assert ti > tk + r.radius  # emitted once its support is complete, not earlier
            assert ti - tk <= r.radius + 0.016 + 1e-9  # and no later than the next sample
            got.append((k, tk, v))
    grid, frames = kernel_resample(t, x, 30.0)
    assert [g[0] for g in got] == list(range(len(grid)))
    np.testing.assert_array_equal(np.array([g[1] for g in got]), grid)
    np.testing.assert_array_equal(np.stack([g[2] for g in got]), frames)
    assert len(r.buf) < 10  # bounded state


def test_kernel_resample_follows_a_smooth_signal_and_bridges_gaps():
    t = _irregular(1000, 2)
    t = np.concatenate([t[t < 3.0], t[t > 3.3]])  # a 0.3 s gap
    x = np.stack([np.sin(2 * np.pi * t), np.full_like(t, 9.81)], axis=1)
    grid, frames = kernel_resample(t, x, 30.0)
    assert np.allclose(np.diff(grid), 1 / 30.0)
    np.testing.assert_allclose(frames[:, 1], 9.81)  # constants stay constant
    ok = (grid > 0.05) & ((grid < 2.95) | (grid > 3.35))
    # a 1 Hz sine through a 17 ms Gaussian: attenuation exp(-(2 pi f sigma)^2 / 2) < 1 %
    assert np.max(np.abs(frames[ok, 0] - np.sin(2 * np.pi * grid[ok]))) < 0.02
    inside = (grid > 3.05) & (grid < 3.25)  # across the gap: between the two ends
    assert inside.any() and np.all(np.abs(frames[inside, 0]) <= 1.0)


def test_session_calibrates_then_streams_the_offline_reconstruction(fitted, phone):
    times, acc, gyro = phone
    s = LiveSession(fitted, calibrate_s=CALIB_S, follow_path=False)  # the model's own root
    frames = []
    for i in range(len(times)):
        out = s.push(times[i], acc[i], gyro[i])
        if s.calibration is None:
            assert not out  # nothing before the calibration
        frames += out
    c = s.calibration
    assert c is not None and c.details[0]["swings"] >= 2
    # the calibration is the offline one on the same first samples
    _, mounts = calibrate(Recording(times[:c.samples], acc[:c.samples], gyro[:c.samples],
                                    ["right_ankle"]))
    np.testing.assert_allclose(c.rotations[0], mounts[0].rotation)
    assert times[c.samples - 1] - times[0] >= CALIB_S > times[c.samples - 2] - times[0]
    # every frame, in order, equal to the offline reconstruction of the same frames
    signals = offline_frames(times, acc, gyro, fitted.fps_, c.rotations)
    offline = fitted.reconstruct_signals(signals).positions()
    assert [f.index for f in frames] == list(range(len(signals)))
    streamed = np.stack([f.positions for f in frames])
    assert streamed.shape == offline.shape == (len(signals), fitted.skeleton_.num_joints, 3)
    np.testing.assert_allclose(streamed, offline, atol=1e-9)
    # the calibrated signals read gravity up the shank: mean specific force along +y
    assert np.mean(signals[:, 1]) > 0.8 * np.linalg.norm(np.mean(signals[:, :3], axis=0))


def test_session_streams_in_the_wearers_height(fitted, phone):
    pytest.importorskip("websockets")
    from imuloco.app.live.server import LiveServer
    from imuloco.measures.gait import stature, to_height

    times, acc, gyro = phone
    server = LiveServer(fitted, calibrate_s=CALIB_S, height_m=1.55,
                        follow_path=False)  # not listening; the model's own root
    server.start_session()
    s = server.session
    assert "1.55 m tall" in server._hello and stature(s.skeleton) == pytest.approx(1.55)
    frames = [f for i in range(len(times)) for f in s.push(times[i], acc[i], gyro[i])]
    # the poses of the offline reconstruction scaled to that height, as reconstruct --height
    signals = offline_frames(times, acc, gyro, fitted.fps_, s.calibration.rotations)
    offline = to_height(fitted.reconstruct_signals(signals), 1.55)
    streamed = np.stack([f.positions for f in frames])
    np.testing.assert_allclose(streamed, offline.positions(), atol=1e-9)
    np.testing.assert_allclose(np.stack([f.root for f in frames]), offline.root, atol=1e-9)
    assert 1.55 / stature(fitted.skeleton_) != pytest.approx(1.0, abs=0.02)  # a real change


class _Late:
    """``fitted`` behind a stream that returns each pose two frames late, as a model with
    look-ahead does."""

    supports_online = True

    def __init__(self, method) -> None:
        self.method = method
        self.name, self.placements_ = method.name, method.placements_
        self.fps_, self.skeleton_ = method.fps_, method.skeleton_

    def stream(self):
        inner, queue = self.method.stream(), []

        class Late:
            delay_frames = 2

            def step(self, sample):
                queue.append(inner.step(sample))
                return queue.pop(0) if len(queue) > 2 else queue[0]

        return Late()


def test_session_labels_a_late_streams_frames_by_the_frame_they_show(fitted, phone):
    times, acc, gyro = phone
    s = LiveSession(_Late(fitted), calibrate_s=0, follow_path=False)  # the model's own root
    frames = [f for i in range(len(times)) for f in s.push(times[i], acc[i], gyro[i])]
    signals = offline_frames(times, acc, gyro, fitted.fps_)
    offline = fitted.reconstruct_signals(signals).positions()
    assert [f.index for f in frames] == list(range(len(signals) - 2))
    np.testing.assert_allclose(np.stack([f.positions for f in frames]), offline[:-2], atol=1e-9)
    np.testing.assert_allclose([f.time for f in frames],
                               times[0] + np.arange(len(frames)) / fitted.fps_, atol=1e-9)


def test_session_refuses_offline_methods_and_drops_old_samples(fitted):
    class Offline:
        name, supports_online = "x", False

    with pytest.raises(ValueError, match="no online mode"):
        LiveSession(Offline())
    s = LiveSession(fitted, calibrate_s=0)
    s.push(1.0, np.zeros(3), np.zeros(3))
    assert s.push(1.0, np.zeros(3), np.zeros(3)) == [] and s.dropped == 1


# ---- the websocket server ------------------------------------------------------------------
async def _stream_through_server(fitted, phone, n_samples: int, timeout: float = 60.0):
    from websockets.asyncio.client import connect

    from imuloco.app.live.server import LiveServer

    times, acc, gyro = phone
    rows = np.concatenate([times[:n_samples, None], acc[:n_samples, 0], gyro[:n_samples, 0]], 1)
    server = LiveServer(fitted, calibrate_s=CALIB_S, follow_path=False)  # the model's root
    await server.start("127.0.0.1", 0)
    base = f"ws://127.0.0.1:{server.port}"
    poses, seen, calibration = [], [], None
    try:
        page = await asyncio.to_thread(
            lambda: urllib.request.urlopen(f"http://127.0.0.1:{server.port}/phone",
                                           timeout=10).read().decode())
        async with connect(base + "/ws/view") as view, connect(base + "/ws/phone") as ph:
            hello = json.loads(await asyncio.wait_for(view.recv(), 10))
            async with connect(base + "/ws/phone") as second:  # one phone at a time
                await asyncio.wait_for(second.wait_closed(), 10)
                assert second.close_code == 1013
            await ph.send("not json")
            err = {"type": None}
            while err["type"] != "error":  # status messages come to the phone too
                err = json.loads(await asyncio.wait_for(ph.recv(), 10))
            for i in range(0, len(rows), 10):
                await ph.send(json.dumps({"rows": rows[i:i + 10].tolist()}))
            expected = len(kernel_resample(times[:n_samples], rows[:, 1:], fitted.fps_)[0])
            loop = asyncio.get_running_loop()
            end = loop.time() + timeout
            while len(poses) < expected:
                msg = json.loads(await asyncio.wait_for(view.recv(), end - loop.time()))
                seen.append(msg["type"])
                if msg["type"] == "pose":
                    poses.append(msg)
                elif msg["type"] == "calibrated":
                    calibration = np.array(msg["rotations"])
    finally:
        await server.close()
    return page, hello, err, poses, seen, calibration


class _Confident(_Late):
    """``fitted`` behind a stream with a made-up confidence: the predicted error cycles through
    1-5 cm, frames of 4 cm or more flagged unreliable."""

    def stream(self):
        from imuloco.methods.base import Stream

        inner = self.method.stream()

        class Confident(Stream):
            k = 0

            def step(self, sample):
                self.k += 1
                self.error_m = 0.01 * (1 + self.k % 5)
                self.unreliable = self.error_m >= 0.04
                return inner.step(sample)

        return Confident()


def test_frames_and_pose_messages_carry_the_streams_confidence(fitted, phone):
    times, acc, gyro = phone
    frames = []
    s = LiveSession(_Confident(fitted), calibrate_s=CALIB_S)
    for i in range(600):
        frames += s.push(times[i], acc[i], gyro[i])
    err = np.array([f.error_m for f in frames])
    assert len(frames) > 20 and set(np.round(err, 3)) == {0.01, 0.02, 0.03, 0.04, 0.05}
    assert [f.unreliable for f in frames] == list(err >= 0.04)
    messages = frames_to_json(frames)
    assert [m["error_m"] for m in messages] == [round(e, 4) for e in err]
    assert [m["unreliable"] for m in messages] == [f.unreliable for f in frames]
    # in the wearer's height, the predicted error (a length) is scaled with the skeleton
    tall = LiveSession(_Confident(fitted), calibrate_s=CALIB_S, height_m=1.95)
    got = [f for i in range(600) for f in tall.push(times[i], acc[i], gyro[i])]
    assert tall.scale > 1.05
    np.testing.assert_allclose([f.error_m for f in got], err * tall.scale)
    assert [f.unreliable for f in got] == [f.unreliable for f in frames]
    # a method without confidence: null, not NaN (browsers' JSON.parse refuses NaN)
    plain = LiveSession(fitted, calibrate_s=CALIB_S)
    out = [f for i in range(600) for f in plain.push(times[i], acc[i], gyro[i])]
    text = json.dumps(frames_to_json(out), allow_nan=False)
    assert all(m["error_m"] is None and m["unreliable"] is False for m in json.loads(text))


def test_server_streams_poses_equal_to_the_offline_method(fitted, phone):
    pytest.importorskip("websockets")
    n = 700  # 7 s: 4 s of calibration, then live frames
    page, hello, err, poses, seen, calibration = asyncio.run(
        asyncio.wait_for(_stream_through_server(fitted, phone, n), 120))
    assert "DeviceMotionEvent" in page and "requestPermission" in page
    sk = fitted.skeleton_
    assert hello["type"] == "skeleton" and hello["parents"] == sk.parents.tolist()
    assert len(hello["sides"]) == sk.num_joints and hello["fps"] == fitted.fps_
    assert err["type"] == "error" and "rows" in err["text"]
    assert seen.index("calibrated") < seen.index("pose")
    assert [p["frame"] for p in poses] == list(range(len(poses)))
    # ridge gives no confidence: every message says so (null, not NaN)
    assert all(p["error_m"] is None and p["unreliable"] is False for p in poses)
    pos = np.array([p["positions"] for p in poses]).reshape(len(poses), sk.num_joints, 3) / 1000
    assert np.isfinite(pos).all()
    times, acc, gyro = phone
    signals = offline_frames(times[:n], acc[:n], gyro[:n], fitted.fps_, calibration)
    offline = fitted.reconstruct_signals(signals).positions()
    np.testing.assert_allclose(pos, offline, atol=0.06e-3)  # sent rounded to 0.1 mm
    # a standing-height figure whose feet stay near the floor
    assert np.all(np.ptp(pos[:, :, 1], axis=1) > 1.0)


async def _replay(fitted, path, timeout: float = 60.0):
    from websockets.asyncio.client import connect

    from imuloco.app.live.server import LiveServer

    server = LiveServer(fitted, calibrate_s=CALIB_S)
    await server.start("127.0.0.1", 0)
    poses = []
    try:
        async with connect(f"ws://127.0.0.1:{server.port}/ws/view") as view:
            await asyncio.wait_for(view.recv(), 10)
            await asyncio.wait_for(server.replay(path, speed=25.0), timeout)
            while True:
                try:
                    msg = json.loads(await asyncio.wait_for(view.recv(), 2))
                except TimeoutError:
                    break
                if msg["type"] == "pose":
                    poses.append(msg)
    finally:
        await server.close()
    return poses


def test_replay_streams_a_recorded_file(fitted, sample_db, tmp_path):
    pytest.importorskip("websockets")
    from imuloco.io.sensorlog import write_generic_csv
    from imuloco.sensors.reallog import read_log

    clip = next(c for c in sample_db.clips if c.name == CLIP)
    path = write_generic_csv(simulate(clip, ["right_ankle"], 100.0, "phone", 12),
                             tmp_path / "walk.csv")
    poses = asyncio.run(_replay(fitted, path))
    rec, _ = read_log(path, rate=None)
    expected = len(kernel_resample(rec.times, rec.channels(), fitted.fps_)[0])
    assert [p["frame"] for p in poses] == list(range(expected))
    assert np.isfinite(np.array([p["positions"] for p in poses])).all()


def test_a_long_pause_restarts_the_model_and_the_walker_stays_where_it_was(fitted, phone):
    pytest.importorskip("websockets")
    from imuloco.app.live.server import LiveServer

    times, acc, gyro = phone
    rows = np.concatenate([times[:, None], acc[:, 0], gyro[:, 0]], 1)
    # the model's own root: the path follower's background thread could land a stride's
    # correction during the pause (timing-dependent); this test is about the model's restart
    server = LiveServer(fitted, calibrate_s=CALIB_S, follow_path=False)  # feed() directly
    server.start_session()
    first = server.feed(rows[:600])
    s = server.session
    calibration, before = s.calibration, s._recent[-1]
    later = rows[600:700].copy()
    later[:, 0] += 5.0  # the page slept for 5 s
    second = server.feed(later)
    assert first > 0 and server.session is s and s.calibration is calibration
    assert s.dropouts == 1 and 0 < second <= 1 + (later[-1, 0] - later[0, 0]) * fitted.fps_
    # frames go on counting on the same grid: the first after the pause is the first due
    k = int(np.ceil((later[0, 0] - rows[0, 0]) * fitted.fps_ - 1e-9))
    assert k > first + 100 and s.resampler.next == k + second
    # over DEAD_RECKON_S: the walker resumes where it stopped, facing the same way
    t, root, yaw = s._recent[-second]
    assert t == pytest.approx(rows[0, 0] + k / fitted.fps_)
    assert np.linalg.norm((root - before[1])[[0, 2]]) < 1e-9 and abs(yaw - before[2]) < 1e-9


def test_the_followed_walker_stands_still_through_a_long_pause(fitted, phone):
    """A walk, then 15 s of the shank standing still (samples on, no dropout): with the path
    followed (the default; its estimate inline, so deterministic) the root holds from 5 s into
    the pause on within 1 mm, 0.3 m at most from where the walk ended, while the model's own
    root (ridge never saw standing) walks on. The sensor is still from 0.8 s in
    (STILL_HOLD_S); the last stride, ending at the pause's first mid-stance, is read at 2 s and
    its correction (the model walked on 1 m past it) blended in by 4 s. Before the still rule
    the followed root walked on with the model (33 m over a 30 s pause)."""
    from imuloco.paths.live import STILL_HOLD_S

    times, acc, gyro = phone
    rng = np.random.default_rng(0)
    tp = times[-1] + 0.01 * np.arange(1, 1501)
    still_acc = acc.mean(axis=0) + rng.normal(0, 0.02, (len(tp), 1, 3))  # gravity, inclined
    still_gyro = rng.normal(0, 0.003, (len(tp), 1, 3))
    t = np.r_[times, tp]
    a, g = np.concatenate([acc, still_acc]), np.concatenate([gyro, still_gyro])
    roots = {}
    for follow in (True, False):
        s = LiveSession(fitted, calibrate_s=CALIB_S, follow_path=follow)
        frames = [f for i in range(len(t)) for f in s.push(t[i], a[i], g[i])]
        assert s.dropouts == 0
        ft = np.array([f.time for f in frames])
        r = np.stack([f.root for f in frames])[:, [0, 2]]
        roots[follow] = r[ft >= times[-1] + 5.0], r[ft <= times[-1]][-1]
        if follow:
            assert s.strides.still() and len(s.strides.read) >= 3  # it walked, then stood
    assert STILL_HOLD_S < 5.0
    pause, walked_to = roots[True]
    held = np.linalg.norm(pause - pause[0], axis=1).max()
    own = np.linalg.norm(roots[False][0][-1] - roots[False][0][0])
    assert held < 1e-3 and own > 1.0, (held, own)
    assert np.linalg.norm(pause[-1] - walked_to) < 0.3


def test_a_one_second_dropout_is_recovered_within_one_second(fitted, sample_db):
    """Pose error against the run without the gap <= 1 cm from at most 1 s of stream time after
    the first sample after the gap on (see imuloco.lab.livebench), on three replays."""
    from imuloco.lab.livebench import dropout_recovery

    clip = next(c for c in sample_db.clips if c.name == CLIP)
    for seed, gap_start in ((11, 4.5), (12, 5.0), (13, 5.5)):
        rec = simulate(clip, ["right_ankle"], rate=100.0, noise="phone", seed=seed)
        r = dropout_recovery(fitted, rec.times, rec.acc, rec.gyro, gap_start, gap_s=1.0,
                             threshold_cm=1.0, calibrate_s=CALIB_S, window_s=2.0)
        assert r.errors_cm[0] > r.threshold_cm  # the restarted model starts off: a real test
        assert r.recovery_s <= 1.0, (seed, r.recovery_s)
        assert np.all(r.errors_cm[r.times_s >= r.recovery_s] <= 1.0)
        assert r.times_s[-1] >= 1.8


def test_session_buffers_stay_bounded_whatever_the_timestamps(fitted):
    from imuloco.app.live.session import MAX_RATE_HZ, RATE_BURST

    s = LiveSession(fitted, calibrate_s=2.0)
    rng = np.random.default_rng(0)
    t, most = 0.0, 0
    for i in range(60_000):  # rows 1e-7 s apart, then 1 ms apart
        t += 1e-7 if i < 30_000 else 1e-3
        s.push(t, rng.normal(size=3), rng.normal(size=3))
        most = max(most, s.buffered)
    assert s.dropped >= 30_000 - 2 * RATE_BURST
    assert most <= (3 * 2.0 + 1) * MAX_RATE_HZ + RATE_BURST + 1
    assert s._raw.nbytes < 2e6  # preallocated for the bound, 56 bytes a row
    with pytest.raises(ValueError, match="calibrate_s"):
        LiveSession(fitted, calibrate_s=1e6)


# ---- access and limits, with the real websockets library on 127.0.0.1 -----------------------
def _serve(fitted, **kwargs):
    """An async context: a LiveServer on a free loopback port and its ws:// base address."""

    from imuloco.app.live.server import LiveServer

    @contextlib.asynccontextmanager
    async def serving():
        server = LiveServer(fitted, calibrate_s=0, **kwargs)
        await server.start("127.0.0.1", 0)
        try:
            yield server, f"ws://127.0.0.1:{server.port}"
        finally:
            await server.close()

    return serving()


async def _refused(url: str, **kwargs) -> tuple[int, str]:
    """Status and body of a refused websocket handshake."""
    from websockets.asyncio.client import connect
    from websockets.exceptions import InvalidStatus

    with pytest.raises(InvalidStatus) as e:
        async with connect(url, **kwargs):
            pass
    return e.value.response.status_code, e.value.response.body.decode()


async def _closed(ws) -> tuple[int, str]:
    """Code and reason the server closed ``ws`` with (reading what came before)."""
    from websockets.exceptions import ConnectionClosed

    try:
        while True:
            await asyncio.wait_for(ws.recv(), 30)
    except ConnectionClosed as e:
        return e.rcvd.code, e.rcvd.reason


def _rows(t: np.ndarray) -> str:
    return json.dumps({"rows": [[ti, 0.0, 9.81, 0.0, 0.0, 0.0, 0.0] for ti in t]})


def test_token_is_required_off_loopback_and_checked_when_given(fitted):
    pytest.importorskip("websockets")
    from websockets.asyncio.client import connect

    async def main():
        async with _serve(fitted, require_token=True) as (server, base):
            token = server.token
            assert len(token) >= 20 and server.urls("localhost")["phone"].endswith(token)
            for path in ("/ws/phone", "/ws/view", f"/ws/view?token={token}x"):
                status, body = await _refused(base + path)
                assert status == 403 and "token" in body
            async with connect(f"{base}/ws/view?token={token}") as view:
                assert json.loads(await asyncio.wait_for(view.recv(), 10))["type"] == "skeleton"
            page = f"http://127.0.0.1:{server.port}/live"
            with pytest.raises(urllib.error.HTTPError) as e:
                await asyncio.to_thread(urllib.request.urlopen, page, timeout=10)
            e.value.close()
            assert e.value.code == 403
            got = await asyncio.to_thread(urllib.request.urlopen, f"{page}?token={token}",
                                          timeout=10)
            got.close()
            assert got.status == 200
        async with _serve(fitted) as (server, base):  # loopback: no token is fine, a wrong no
            assert not server.require_token
            async with connect(base + "/ws/view") as view:
                assert json.loads(await asyncio.wait_for(view.recv(), 10))["type"] == "skeleton"
            status, body = await _refused(base + "/ws/phone?token=guess")
            assert status == 403 and "wrong token" in body
            assert server.phone is None

    asyncio.run(main())


def test_other_origins_and_hosts_are_refused(fitted):
    pytest.importorskip("websockets")
    from websockets.asyncio.client import connect

    async def main():
        async with _serve(fitted, allow_origins=["https://viewer.example:9000/"]) as (
                server, base):
            own = f"http://127.0.0.1:{server.port}"
            status, body = await _refused(base + "/ws/phone", origin="https://evil.example")
            assert status == 403 and "Origin" in body and "--allow-origin" in body
            status, _ = await _refused(base + "/ws/view", origin="null")
            assert status == 403 and server.phone is None and not server.viewers
            for origin in (own, "https://viewer.example:9000"):
                async with connect(base + "/ws/view", origin=origin) as view:
                    assert json.loads(await asyncio.wait_for(view.recv(), 10))["type"] == \
                        "skeleton"
            # DNS rebinding: a page whose own name now resolves to 127.0.0.1
            req = urllib.request.Request(f"{own}/live", headers={"Host": "evil.example:80"})
            with pytest.raises(urllib.error.HTTPError) as e:
                await asyncio.to_thread(urllib.request.urlopen, req, timeout=10)
            body = e.value.read()
            e.value.close()
            assert e.value.code == 403 and b"loopback" in body

    asyncio.run(main())


def test_limits_close_the_connection_with_a_code_and_a_reason(fitted, caplog):
    pytest.importorskip("websockets")
    from websockets.asyncio.client import connect

    from imuloco.app.live.server import Limits

    limits = Limits(max_bytes=64 * 1024, max_rows=100, messages_per_s=1.0, max_viewers=2)

    async def phone_closed(base, *messages) -> tuple[int, str]:
        async with connect(base + "/ws/phone", max_size=None) as ph:
            for m in messages:
                await ph.send(m)
            return await _closed(ph)

    async def main():
        async with _serve(fitted, limits=limits) as (_, base):
            noise = np.random.default_rng(0).normal(size=(14_000, 6))
            rows = np.round(np.c_[np.arange(14_000) * 0.01, noise], 6)
            one_mib = json.dumps({"rows": rows.tolist()})  # 14k rows, about 1 MiB
            assert len(one_mib) > 2**20 * 0.9
            code, reason = await phone_closed(base, one_mib)
            assert code == 1009 and "exceeds limit" in reason
            code, reason = await phone_closed(base, _rows(np.arange(101) * 0.01))
            assert code == 1009 and "101 rows" in reason
            code, reason = await phone_closed(base, *[_rows([0.01 * i]) for i in range(50)])
            assert code == 1008 and "messages/s" in reason
        async with _serve(fitted, limits=Limits()) as (_, base):
            # rows 0.9 s apart: 90 s of samples at once, faster than real time
            code, reason = await phone_closed(base, _rows(np.arange(100) * 0.9))
            assert code == 1008 and "real time" in reason
        async with _serve(fitted, limits=limits) as (_, base), \
                connect(base + "/ws/view") as a, connect(base + "/ws/view") as b:
            async with connect(base + "/ws/view") as c:
                assert await _closed(c) == (1013, "too many viewers (at most 2)")
            await a.send("hello")
            assert await _closed(a) == (1008, "viewers only listen on /ws/view")
            assert json.loads(await asyncio.wait_for(b.recv(), 10))["type"] == "skeleton"

    with caplog.at_level("INFO", logger="imuloco"):
        asyncio.run(main())
    closing = [r.getMessage() for r in caplog.records if r.getMessage().startswith("closing")]
    assert len(closing) == 5  # one line per connection a limit closed (1009 is websockets')


def test_a_phone_closed_for_a_limit_frees_its_place_at_once(fitted, phone):
    """A phone that broke a limit and does not read (its closing handshake pending) does not
    keep the next phone out: the next one streams at once and viewers see its poses."""
    pytest.importorskip("websockets")
    from websockets.asyncio.client import connect

    from imuloco.app.live.server import Limits

    times, acc, gyro = phone
    rows = np.concatenate([times[:, None], acc[:, 0], gyro[:, 0]], axis=1)

    async def main():
        async with _serve(fitted, limits=Limits(messages_per_s=1.0)) as (server, base), \
                connect(base + "/ws/view") as view, connect(base + "/ws/phone") as rude:
            for i in range(50):  # never reads what the server says
                await rude.send(_rows([0.01 * i]))
            for _ in range(300):  # the place is free well before websockets' 10 s
                if server.phone is None:
                    break
                await asyncio.sleep(0.01)
            assert server.phone is None
            # another client (limits are per client: the rude one's allowance is spent)
            async with connect(base + "/ws/phone", max_size=None,
                               local_addr=("127.0.0.2", 0)) as polite:
                await polite.send(json.dumps({"rows": rows[:400].tolist()}))
                kinds = set()
                while "pose" not in kinds:
                    kinds.add(json.loads(await asyncio.wait_for(view.recv(), 20))["type"])
                assert server.phone is not None

    asyncio.run(main())


def test_rows_closer_than_the_rate_limit_do_not_grow_the_servers_buffers(fitted):
    pytest.importorskip("websockets")
    from websockets.asyncio.client import connect

    from imuloco.app.live.session import RATE_BURST

    async def main():
        async with _serve(fitted) as (server, base), connect(base + "/ws/phone") as ph:
            for i in range(20):  # 20 messages of 1000 rows 1e-7 s apart
                await ph.send(_rows(i * 1e-4 + np.arange(1000) * 1e-7))
            await ph.send(_rows([1.0]))
            while server.session.last_t != 1.0:  # the worker has taken every message
                await asyncio.sleep(0.01)
            s = server.session
            assert s.dropped >= 20_000 - 3 * RATE_BURST and s.buffered <= 3 * RATE_BURST

    asyncio.run(asyncio.wait_for(main(), 120))


def test_the_model_runs_off_the_event_loop(fitted):
    pytest.importorskip("websockets")
    import threading

    from websockets.asyncio.client import connect

    from imuloco.methods.base import Stream

    threads = set()

    class Recorded(_Late):
        def stream(self):
            inner = self.method.stream()

            class S(Stream):
                def step(self, sample):
                    threads.add(threading.current_thread().name)
                    return inner.step(sample)

            return S()

    async def main():
        async with _serve(Recorded(fitted)) as (_, base), connect(base + "/ws/view") as view, \
                connect(base + "/ws/phone") as ph:
            await ph.send(_rows(np.arange(100) * 0.01))
            while True:
                msg = json.loads(await asyncio.wait_for(view.recv(), 30))
                if msg["type"] == "pose":
                    break
            return threading.current_thread().name

    loop_thread = asyncio.run(main())
    assert threads and loop_thread not in threads
    assert all(name.startswith("imuloco-live-model") for name in threads)


def test_a_dropped_viewer_is_one_log_line(fitted, phone, caplog):
    """A viewer whose connection is lost while poses stream: one line from the server, none of
    asyncio's 'socket.send() raised exception' per pose."""
    pytest.importorskip("websockets")
    from websockets.asyncio.client import connect

    times, acc, gyro = phone
    rows = np.concatenate([times[:, None], acc[:, 0], gyro[:, 0]], 1)

    async def main():
        async with _serve(fitted) as (server, base):
            async with connect(base + "/ws/view") as view:
                await asyncio.wait_for(view.recv(), 10)
                (ws,) = server.viewers
                ws.transport.abort()  # the network dropped it; websockets has not noticed yet
                server.start_session()
                frames = server.feed(rows[:300])  # ~90 poses at it
                while server.viewers:
                    await asyncio.sleep(0.01)
            return frames

    with caplog.at_level("INFO"):
        frames = asyncio.run(asyncio.wait_for(main(), 60))
    assert frames > 50
    lines = [r.getMessage() for r in caplog.records]
    assert not [m for m in lines if "socket.send()" in m]
    assert len([m for m in lines if m.startswith("viewer ")]) == 1


# ---- the pages in a real headless browser (skipped without selenium and Debian chromium) -----
@pytest.fixture
def threaded_server(fitted, serve_threaded):
    """A LiveServer listening on a free loopback port, its event loop in a thread."""
    with serve_threaded(fitted, CALIB_S) as served:
        yield served


def test_live_page_is_served_with_the_viewers_stick_figure_script(threaded_server):
    from imuloco.viz.html import STICKFIGURE

    server, _ = threaded_server

    def get(path: str) -> str:
        url = f"http://127.0.0.1:{server.port}{path}"
        with urllib.request.urlopen(url, timeout=10) as response:
            return response.read().decode()

    js = STICKFIGURE.read_text()
    for path in ("/", "/live"):
        page = get(path)
        assert page.count(js) == 1 and "__IMULOCO_" not in page
        assert page.index("const StickFigure") < page.index("StickFigure.projector")
        assert "<script src" not in page  # one request, nothing else to fetch
    assert "StickFigure" not in get("/phone")


def test_phone_page_sends_device_motion_in_si_units(threaded_server, browser, wait_for):
    from selenium.webdriver.common.by import By

    server, _ = threaded_server
    received = []
    process = server.process  # runs in the server's worker thread
    server.process = lambda rows: (received.append(rows.copy()), process(rows))[1]
    browser.get(f"http://127.0.0.1:{server.port}/phone")
    browser.find_element(By.ID, "start").click()
    wait_for(lambda: server.phone is not None)
    # a phone lying on its back, turning: m/s^2 with gravity, rotationRate in deg/s
    browser.execute_script("""
        for (let i = 0; i < 20; i++) {
          window.dispatchEvent(new DeviceMotionEvent("devicemotion", {
            accelerationIncludingGravity: {x: 0.5, y: -1.0, z: 9.8},
            rotationRate: {alpha: 90, beta: 180, gamma: -45}, interval: 10}));
        }""")
    wait_for(lambda: sum(len(r) for r in received) >= 20)
    rows = np.concatenate(received)
    assert np.all(np.diff(rows[:, 0]) >= 0) and rows[0, 0] > 0  # seconds, not ms
    assert rows[-1, 0] - rows[0, 0] < 5.0
    # acc as given; gyro about x, y, z = beta, gamma, alpha, in rad/s
    np.testing.assert_allclose(rows[:, 1:], np.tile([0.5, -1.0, 9.8, np.pi, -np.pi / 4,
                                                    np.pi / 2], (len(rows), 1)))
    assert "connected" in browser.find_element(By.ID, "status").text or \
        "calibrating" in browser.find_element(By.ID, "status").text
    assert not [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]


def test_live_page_draws_the_replayed_walker(threaded_server, browser, sample_db, tmp_path,
                                             wait_for):
    from imuloco.io.sensorlog import write_generic_csv

    server, loop = threaded_server
    clip = next(c for c in sample_db.clips if c.name == CLIP)
    path = write_generic_csv(simulate(clip, ["right_ankle"], 100.0, "phone", 13),
                             tmp_path / "walk.csv")
    browser.get(f"http://127.0.0.1:{server.port}/live")
    wait_for(lambda: browser.execute_script("return imuloco.state().skel !== null"))
    replay = asyncio.run_coroutine_threadsafe(server.replay(path, speed=4.0), loop)
    wait_for(lambda: browser.execute_script("return imuloco.state().pose !== null"))
    first = browser.execute_script("return imuloco.state().pose")
    wait_for(lambda: browser.execute_script("return imuloco.state().pose")[0] != first[0])
    replay.result(60)
    state = browser.execute_script("return imuloco.state()")
    assert len(state["pose"]) == 3 * fitted_joints(server)
    assert state["floor"] < min(state["pose"][1::3]) + 0.05  # the floor under the feet
    # the walker is drawn: the canvas holds pixels of the left (blue) and right (red) bones
    colours = browser.execute_script("""
        imuloco.draw();
        const c = document.getElementById('view');
        const px = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
        let blue = 0, red = 0;
        for (let i = 0; i < px.length; i += 4) {
          if (px[i] === 0x1f && px[i + 1] === 0x77 && px[i + 2] === 0xb4) blue++;
          if (px[i] === 0xd6 && px[i + 1] === 0x27 && px[i + 2] === 0x28) red++;
        }
        return [blue, red];""")
    assert min(colours) > 20, colours
    # the viewer's orbit controls: a drag turns the camera
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By

    before = browser.execute_script("return imuloco.view.azimuth")
    ActionChains(browser).move_to_element(browser.find_element(By.ID, "view")).click_and_hold() \
        .move_by_offset(120, 0).release().perform()
    assert browser.execute_script("return imuloco.view.azimuth") == pytest.approx(before - 1.2)
    browser.save_screenshot(str(tmp_path / "live.png"))
    assert (tmp_path / "live.png").stat().st_size > 5000
    assert not [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]


def fitted_joints(server) -> int:
    return server.method.skeleton_.num_joints


def test_calibration_waits_for_the_walk_and_takes_up_from_standing(fitted, phone):
    times, acc, gyro = phone
    q = from_rotvec(np.array([0.4, -1.2, 2.0]))  # the phone's mounting (see the fixture)
    rng = np.random.default_rng(4)
    n = 600  # 6 s standing still, the shank vertical: gravity up the segment's y
    t_still = np.arange(n) * 0.01
    acc_still = qrot(q, np.array([0.0, 9.81, 0.0])) + rng.normal(0, 0.02, (n, 1, 3))
    gyro_still = rng.normal(0, 0.005, (n, 1, 3))
    s = LiveSession(fitted, calibrate_s=CALIB_S)
    for i in range(n):
        assert s.push(t_still[i], acc_still[i], gyro_still[i]) == []
    assert s.calibration is None and "walk" in s.describe()  # no swing yet: still waiting
    frames = []
    for i in range(len(times)):
        frames += s.push(times[i] + 6.0, acc[i], gyro[i])
        if s.calibration is not None:
            break
    c = s.calibration
    assert c is not None and c.details[0]["up_from"] == "still" and c.details[0]["swings"] >= 2
    assert c.seconds < 3 * CALIB_S and frames and frames[0].index == 0
    # gravity at rest now reads straight up the segment
    np.testing.assert_allclose(qrot(c.rotations[0], qrot(q, np.array([0.0, 9.81, 0.0]))),
                               [0.0, 9.81, 0.0], atol=0.05)


def test_a_shoe_sensor_is_calibrated_from_its_strides_then_streamed(sample_db):
    """A foot sensor in any orientation: the session calibrates it as the offline pipeline does
    (up from the resting foot, forward from its strides) once two strides are in, then
    streams the shipped foot model."""
    pytest.importorskip("gaitmap")
    from imuloco.app.pipeline import choose_method

    fitted, _ = choose_method(placement="right_foot")
    clip = next(c for c in sample_db.clips if c.name == CLIP)
    rec = simulate(clip, ["right_foot"], rate=100.0, noise="phone", seed=11)
    q = from_rotvec(np.array([-2.1, 0.3, 0.9]))
    times, acc, gyro = rec.times, qrot(q, rec.acc), qrot(q, rec.gyro)
    s = LiveSession(fitted, calibrate_s=CALIB_S)
    frames = []
    for i in range(len(times)):
        frames += s.push(times[i], acc[i], gyro[i])
    c = s.calibration
    assert c is not None and c.details[0]["up_from"] == "stances" and frames
    _, mounts = calibrate(Recording(times[:c.samples], acc[:c.samples], gyro[:c.samples],
                                    ["right_foot"]))
    np.testing.assert_allclose(c.rotations[0], mounts[0].rotation)
    # gravity at rest on the flat foot reads as on the virtual foot sensor: up and back along
    # its bones' slope, nothing sideways
    up = qrot(c.rotations[0], qrot(q, rec.acc[0, 0]))
    assert abs(up[0]) < 1.5 and up[1] > 3.0 and up[2] > 5.0, up


def test_live_page_shows_the_predicted_error_and_flags(fitted, browser, sample_db, tmp_path,
                                                      wait_for, serve_threaded, count_pixels_js):
    """Pose messages carry the stream's confidence through the server to the page, which
    writes the predicted error and tints a flagged walker."""
    from imuloco.io.sensorlog import write_generic_csv
    from imuloco.viz.html import UNRELIABLE_LABEL

    clip = next(c for c in sample_db.clips if c.name == CLIP)
    path = write_generic_csv(simulate(clip, ["right_ankle"], 100.0, "phone", 13),
                             tmp_path / "walk.csv")
    with serve_threaded(_Confident(fitted), CALIB_S) as (server, loop):
        browser.get(f"http://127.0.0.1:{server.port}/live")
        wait_for(lambda: browser.execute_script("return imuloco.state().skel !== null"))
        browser.get_log("browser")  # drop what earlier tests' pages logged
        replay = asyncio.run_coroutine_threadsafe(server.replay(path, speed=1.0), loop)
        seen = {True: None, False: None}

        def both() -> bool:
            got = browser.execute_script(count_pixels_js + """
                const amber = countPixels(255, 176, 0);
                const line = document.getElementById('confidence');
                return [imuloco.state().confidence, line.textContent, line.className, amber];""")
            if got[0]["errorM"] is not None and seen[got[0]["unreliable"]] is None:
                seen[got[0]["unreliable"]] = got
            return all(seen.values())

        wait_for(both, 60)
        replay.result(60)
        assert not [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]
    (c, text, cls, amber), (c2, text2, cls2, amber2) = seen[True], seen[False]
    assert c["errorM"] >= 0.04 and text.endswith(UNRELIABLE_LABEL)
    assert text.startswith(f"predicted error {100 * c['errorM']:.1f} cm")
    assert cls == "unreliable" and amber > 50
    assert c2["errorM"] < 0.04 and text2 == f"predicted error {100 * c2['errorM']:.1f} cm"
    assert cls2 == "" and amber2 == 0
