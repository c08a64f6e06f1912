"""Measurements of the live mode (``imuloco bench live``): recovery after a sensor dropout,
and a loopback load test of the server under an abusive client.

Dropout recovery. One recording is streamed through :class:`LiveSession` twice: whole, and
with ``gap_s`` seconds of samples removed from ``gap_start`` on. The walker has *recovered* at
the first frame after the gap from which, for the rest of the compared window, the pose error
against the whole run's frame of the same number stays at or below ``threshold_cm``. The pose
error is the MPJPE of :func:`imuloco.measures.metrics.joint_errors` (joint positions relative
to the pelvis in the heading frame, all joints but the root, cm). The recovery time counts
stream seconds from the first sample after the gap, so it does not depend on the machine.
Where the walker stands is reported beside it: the horizontal distance between the two runs'
roots and the difference of their headings at the end of the window.
"""

from __future__ import annotations

import asyncio
import json
import logging
import multiprocessing
import os
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from imuloco.app.live.server import LiveServer
from imuloco.app.live.session import Frame, LiveSession
from imuloco.app.pipeline import choose_method
from imuloco.core.motion import Motion
from imuloco.io.atomic import atomic_write
from imuloco.io.database import load_sample
from imuloco.measures.metrics import heading_of, joint_errors
from imuloco.sensors.simulate import simulate


@dataclass
class Recovery:
    """How the walker came back after a dropout (see the module docstring).

    gap_start, gap_s : the dropout, seconds on the recording's clock and its length.
    recovery_s : stream seconds from the first sample after the gap until the pose error stays
        at or below ``threshold_cm`` (``inf``: not within the window).
    errors_cm : (K,) pose error of each compared frame after the gap; times_s : (K,) their
        times in seconds after the first sample after the gap.
    root_offset_m, heading_offset_deg : the runs' roots (horizontal distance) and headings
        apart at the last compared frame.
    """

    gap_start: float
    gap_s: float
    threshold_cm: float
    recovery_s: float
    errors_cm: np.ndarray
    times_s: np.ndarray
    root_offset_m: float
    heading_offset_deg: float

    def to_json(self) -> dict:
        d = asdict(self)
        d["errors_cm"] = np.round(self.errors_cm, 3).tolist()
        d["times_s"] = np.round(self.times_s, 4).tolist()
        return d


def _stream(method, times: np.ndarray, acc: np.ndarray, gyro: np.ndarray,
            calibrate_s: float) -> dict[int, Frame]:
    s = LiveSession(method, calibrate_s)
    return {f.index: f for i in range(len(times)) for f in s.push(times[i], acc[i], gyro[i])}


def dropout_recovery(method, times: np.ndarray, acc: np.ndarray, gyro: np.ndarray,
                     gap_start: float, gap_s: float = 1.0, threshold_cm: float = 1.0,
                     calibrate_s: float = 4.0, window_s: float = 2.0) -> Recovery:
    """Recovery after removing ``gap_s`` seconds of samples from ``gap_start`` on.

    Parameters
    ----------
    method : a fitted online method.
    times : ndarray, shape (N,), seconds; acc, gyro : ndarray, shape (N, S, 3), the phone's
        raw samples (m/s^2, rad/s) as :meth:`LiveSession.push` takes them.
    window_s : seconds after the gap compared (the recording must reach that far).
    """
    keep = (times < gap_start) | (times >= gap_start + gap_s)
    whole = _stream(method, times, acc, gyro, calibrate_s)
    gapped = _stream(method, times[keep], acc[keep], gyro[keep], calibrate_s)
    resume = float(times[keep][np.searchsorted(times[keep], gap_start)])
    after = sorted(k for k, f in gapped.items() if k in whole and f.time >= resume
                   and f.time <= resume + window_s)
    if len(after) < 2 or gapped[after[-1]].time < resume + 0.9 * window_s:
        raise ValueError(f"the recording ends before {window_s} s after the gap")
    sk, fps = method.skeleton_, float(method.fps_)

    def motion(frames: dict[int, Frame]) -> Motion:
        return Motion(sk, np.stack([frames[k].rotations for k in after]),
                      np.stack([frames[k].root for k in after]), fps)

    a, b = motion(whole), motion(gapped)
    errors = joint_errors(a, b)[:, 1:].mean(axis=1) * 100.0
    t = np.array([gapped[k].time for k in after]) - resume
    over = np.flatnonzero(errors > threshold_cm)
    if len(over) == 0:
        recovery = float(t[0])
    elif over[-1] == len(t) - 1:
        recovery = float("inf")
    else:
        recovery = float(t[over[-1] + 1])
    heading = np.degrees(heading_of(a)[-1] - heading_of(b)[-1])
    return Recovery(gap_start, gap_s, threshold_cm, recovery, errors, t,
                    float(np.linalg.norm((a.root[-1] - b.root[-1])[[0, 2]])),
                    float((heading + 180.0) % 360.0 - 180.0))


# ---- the loopback load test --------------------------------------------------------------------
def _rss_mb(pid: int) -> float:
    """Resident memory of a process, MB (Linux /proc; psutil would add a dependency)."""
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    raise OSError(f"no VmRSS for process {pid}")


def _cpu_s(pid: int) -> float:
    """CPU seconds (user + system) a process has used (Linux /proc)."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


class _Counter(logging.Handler):
    """Counts the server's log lines, and asyncio's 'socket.send() raised exception'."""

    def __init__(self) -> None:
        super().__init__()
        self.lines: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.lines.append(f"{record.name}: {record.getMessage()}")


def _server_process(conn, calibrate_s: float) -> None:
    """Child process: a LiveServer on 127.0.0.1; sends its port, serves until told to stop,
    sends back its log lines."""
    counter = _Counter()
    logging.getLogger().addHandler(counter)
    logging.getLogger().setLevel(logging.INFO)
    logging.getLogger("websockets").setLevel(logging.WARNING)
    method, _ = choose_method()

    async def main() -> None:
        server = LiveServer(method, calibrate_s)
        await server.start("127.0.0.1", 0)
        conn.send(server.port)
        loop = asyncio.get_running_loop()
        await loop.run_in_executor(None, conn.recv)  # until the parent says stop
        skipped = sum(server.skipped.values())
        await server.close()
        conn.send({"log": counter.lines, "skipped_poses_open_viewers": skipped})

    asyncio.run(main())


def walk_rows(seconds: float, seed: int = 0) -> np.ndarray:
    """Phone rows (N, 7) of the bundled sample's walks simulated at 100 Hz on the right shank
    (segment axes: no calibration needed), one after the other for ``seconds``."""
    clips = [c for c in load_sample().clips if c.name.startswith("dataset-2_walk_")]
    parts, t0, i = [], 0.0, 0
    while t0 < seconds:
        rec = simulate(clips[i % len(clips)], ["right_ankle"], 100.0, "phone", seed + i)
        t = rec.times - rec.times[0] + t0
        parts.append(np.concatenate([t[:, None], rec.acc[:, 0], rec.gyro[:, 0]], axis=1))
        t0, i = t[-1] + 0.01, i + 1
    rows = np.concatenate(parts)
    return rows[rows[:, 0] < seconds]


async def _load(port: int, pid: int, rows: np.ndarray, viewers: int, seconds: float,
                abuse: bool) -> dict:
    from websockets.asyncio.client import connect  # the [live] extra's
    from websockets.exceptions import ConnectionClosed, InvalidStatus

    base = f"ws://127.0.0.1:{port}"
    loop = asyncio.get_running_loop()
    poses = [[] for _ in range(viewers)]  # arrival times
    dropped: list[str] = []
    closures: list[str] = []
    sockets: list = []  # the viewers' connections
    rss: list[tuple[float, float]] = []
    stop = asyncio.Event()

    async def viewer(i: int) -> None:
        try:
            async with connect(base + "/ws/view", max_size=None) as ws:
                sockets.append(ws)
                async for m in ws:
                    if m.startswith('{"type":"pose"'):
                        poses[i].append(loop.time())
        except ConnectionClosed as e:
            dropped.append(f"viewer {i}: {e}")

    async def memory() -> None:
        while not stop.is_set():
            rss.append((loop.time(), _rss_mb(pid)))
            await asyncio.sleep(0.25)

    def message(r: np.ndarray) -> str:
        return json.dumps({"rows": r.tolist()})

    async def phone() -> None:
        """Streams rows at real time; the abuse (if any) on the same connection, reconnecting
        after each close."""
        start, i = loop.time(), 0
        readers: list[asyncio.Task] = []
        plan = [(0.35, "1 MiB message"), (0.5, "rows 1e-7 s apart"), (0.65, "high rate"),
                (0.8, "second phone and a talking viewer")] if abuse else []
        while i < len(rows):
            try:
                async with connect(base + "/ws/phone", max_size=None) as ws:
                    # read the server's status messages as the phone page does: unread, they
                    # fill the client's queue and its closing handshake waits 10 s behind them
                    readers.append(asyncio.create_task(_drain(ws)))
                    while i < len(rows):
                        now = loop.time() - start
                        j = int(np.searchsorted(rows[:, 0], now, side="right"))
                        if j > i:
                            await ws.send(message(rows[i:j]))
                            i = j
                        if plan and now > plan[0][0] * seconds:
                            what = plan.pop(0)[1]
                            await _abuse(what, ws, rows[max(i - 1, 0), 0], base, connect)
                        await asyncio.sleep(0.02)
            except ConnectionClosed as e:
                closures.append(f"phone: {e.rcvd.code if e.rcvd else None} "
                                f"{e.rcvd.reason if e.rcvd else ''}")
            except InvalidStatus as e:
                closures.append(f"phone refused: {e}")
            await asyncio.sleep(0.1)  # reconnect, as the phone page does
        await asyncio.gather(*readers)

    tasks = [asyncio.create_task(viewer(i)) for i in range(viewers)]
    mem = asyncio.create_task(memory())
    await asyncio.sleep(1.0)
    start, cpu = loop.time(), _cpu_s(pid)
    await phone()
    end, cpu = loop.time(), _cpu_s(pid) - cpu
    await asyncio.sleep(0.5)
    stop.set()
    await asyncio.gather(*(ws.close() for ws in sockets))  # viewers leave (1000)
    if tasks:
        await asyncio.wait(tasks, timeout=10)
    for t in tasks:
        t.cancel()
    await mem
    window = (start + 2.0, end)  # after the first poses are due
    rates = [sum(window[0] <= x <= window[1] for x in p) / (window[1] - window[0])
             for p in poses]
    warm = [m for t, m in rss if t <= start + 0.3 * seconds]
    return {"viewers": viewers, "seconds": seconds, "viewers_dropped": len(dropped),
            "dropped": dropped[:10], "phone_closures": closures,
            "pose_rate": {"min": min(rates, default=0.0),
                          "median": float(np.median(rates)) if rates else 0.0,
                          "max": max(rates, default=0.0)},
            "rss_mb": {"before_phone": rss[0][1], "warm": max(warm), "max": max(m for _, m in rss),
                       "end": rss[-1][1]},
            "growth_mb": max(m for _, m in rss) - max(warm),
            "server_cpu_share": cpu / (end - start),  # of one core, over the phone's run
            "run_s": end - start}


async def _drain(ws) -> None:
    """Read and drop a connection's incoming messages until it closes."""
    from websockets.exceptions import ConnectionClosed  # the [live] extra's

    try:
        async for _ in ws:
            pass
    except ConnectionClosed:
        pass


async def _abuse(what: str, ws, t: float, base: str, connect) -> None:
    """One of the abusive client's moves (see :func:`load_test`)."""
    if what == "1 MiB message":
        rng = np.random.default_rng(0)
        r = np.round(np.c_[t + 0.001 + np.arange(14_000) * 0.01, rng.normal(size=(14_000, 6))], 6)
        await ws.send(json.dumps({"rows": r.tolist()}))
    elif what == "rows 1e-7 s apart":
        for k in range(20):
            r = np.c_[t + 1e-4 * k + np.arange(1000) * 1e-7, np.zeros((1000, 6))]
            await ws.send(json.dumps({"rows": r.tolist()}))
    elif what == "high rate":
        for k in range(2000):
            await ws.send(json.dumps({"rows": [[t + 1e-3 * (k + 1)] + [0.0] * 6]}))
    else:
        from websockets.exceptions import ConnectionClosed  # the [live] extra's

        try:
            async with connect(base + "/ws/phone") as second:
                await second.wait_closed()
            async with connect(base + "/ws/view") as talker:
                await talker.send("x" * 2**20)
                await talker.wait_closed()
        except ConnectionClosed:
            pass


def load_test(viewers: int = 100, seconds: float = 20.0, abuse: bool = True,
              calibrate_s: float = 0.0) -> dict:
    """``viewers`` viewers and one phone streaming a simulated walk at real time for
    ``seconds`` to a server in a child process on 127.0.0.1, while the same phone (with
    ``abuse``) sends a 1 MiB message (closed, it reconnects), 20 messages of 1000 rows
    1e-7 s apart, 2000 one-row messages as fast as it can (closed, it reconnects), and another
    client tries a second phone and talks on a viewer socket. Returns the figures: viewers
    dropped, pose rate each viewer received (poses per second over the run after its first
    2 s), the server's resident memory (MB: before the phone, its maximum over the first 30 %
    of the run before any abuse, its maximum, at the end; growth = maximum - warm), its log
    lines and how the phone's connections ended."""
    ctx = multiprocessing.get_context("spawn")
    parent, child = ctx.Pipe()
    proc = ctx.Process(target=_server_process, args=(child, calibrate_s), daemon=True)
    proc.start()
    try:
        if not parent.poll(120):
            raise RuntimeError("the live server did not start within 120 s")
        port = parent.recv()
        result = asyncio.run(_load(port, proc.pid, walk_rows(seconds), viewers, seconds, abuse))
        parent.send("stop")
        report = parent.recv() if parent.poll(60) else {"log": []}
    finally:
        proc.join(30)
        if proc.is_alive():
            proc.terminate()
            proc.join(10)
    lines = report["log"]
    result.update(server_log_lines=len(lines), server_log=lines[:60],
                  socket_send_warnings=sum("socket.send()" in x for x in lines),
                  skipped_poses_open_viewers=report.get("skipped_poses_open_viewers"))
    return result


DROPOUT_CLIPS = ("dataset-2_walk_normal_001", "dataset-2_walk_exhausted_001",
                 "dataset-2_walk-turn-right_exhausted_001")


def dropouts(threshold_cm: float = 1.0) -> dict:
    """:func:`dropout_recovery` of the default model after 1 s dropouts 4.5, 5 and 5.5 s into
    three bundled walks (:data:`DROPOUT_CLIPS`, a simulated right-ankle phone): the mean and
    largest recovery time and offsets, and each run's ``details``."""
    method, note = choose_method()
    clips = [c for c in load_sample().clips if c.name in DROPOUT_CLIPS]
    runs = []
    for clip in clips:
        rec = simulate(clip, ["right_ankle"], 100.0, "phone", 11)
        for start in (4.5, 5.0, 5.5):
            if rec.times[-1] < start + 1.0 + 2.1:
                continue
            r = dropout_recovery(method, rec.times, rec.acc, rec.gyro, start, 1.0, threshold_cm)
            runs.append({"clip": clip.name, **r.to_json()})
    rec_s = np.array([r["recovery_s"] for r in runs])
    return {"model": note, "threshold_cm": threshold_cm, "runs": len(runs),
            "recovery_s": {"mean": float(rec_s.mean()), "max": float(rec_s.max())},
            "root_offset_m": {"mean": float(np.mean([r["root_offset_m"] for r in runs])),
                              "max": float(np.max([r["root_offset_m"] for r in runs]))},
            "heading_offset_deg": {"mean_abs": float(np.mean(
                [abs(r["heading_offset_deg"]) for r in runs]))},
            "details": runs}


def live_benchmark(out: str | Path, viewers: int = 100, seconds: float = 20.0,
                   abuse: bool = True) -> tuple[dict, dict]:
    """:func:`load_test` then :func:`dropouts`; writes ``load.json`` and ``dropout.json`` into
    ``out`` and returns both records."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    load = load_test(viewers, seconds, abuse=abuse)
    with atomic_write(out / "load.json", "w") as f:
        f.write(json.dumps(load, indent=1))
    drop = dropouts()
    with atomic_write(out / "dropout.json", "w") as f:
        f.write(json.dumps(drop, indent=1))
    return load, drop


def summaries(load: dict, drop: dict) -> str:
    """The two records' figures as printed: JSON without the server's log, the dropped
    viewers' list and each dropout run."""
    return "\n".join(json.dumps({k: v for k, v in record.items() if k not in skip}, indent=1)
                     for record, skip in ((load, ("server_log", "dropped")), (drop, ("details",))))
