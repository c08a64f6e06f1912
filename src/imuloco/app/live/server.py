"""The live server: a phone streams its motion sensors over a websocket, browsers watch the
reconstructed walker as it walks.

One asyncio ``websockets`` server (the ``[live]`` extra) on one port serves

* ``/phone`` (``phone.html``): the page the phone opens; it reads the browser's
  ``DeviceMotionEvent`` and sends samples to ``/ws/phone``;
* ``/`` and ``/live`` (``live.html``): the live stick figure, fed by ``/ws/view``, drawn by the
  offline viewer's ``imuloco/viz/stickfigure.js``, inlined into the page as it is served;
* ``/ws/phone``: JSON messages ``{"rows": [[t, ax, ay, az, gx, gy, gz, ...], ...]}``, time in
  seconds on the phone's clock, specific force in m/s^2 and angular velocity in rad/s in the
  phone's axes, six values per sensor of the model's placements (one for a phone);
* ``/ws/view``: a ``skeleton`` message on connection, then ``status``, ``reset`` and ``pose``
  messages (:func:`imuloco.app.live.session.frames_to_json`).

One phone streams at a time; each phone connection starts a fresh
:class:`~imuloco.app.live.session.LiveSession`. :meth:`LiveServer.replay` streams a recorded log at
real time through the same path instead of a phone.

Browsers expose motion sensors to secure pages only: ``http://localhost`` is one, but a phone
reaching a laptop over the network needs HTTPS (``certfile``/``keyfile``, a self-signed
certificate will do once accepted on the phone).
"""

from __future__ import annotations

import asyncio
import functools
import http
import json
import logging
import ssl as ssl_module
import time
from pathlib import Path

import numpy as np
from websockets.asyncio.server import Server, ServerConnection, broadcast, serve
from websockets.exceptions import ConnectionClosed
from websockets.http11 import Request, Response

from imuloco.app.live.session import LiveSession, frames_to_json
from imuloco.viz.html import inline_stickfigure

log = logging.getLogger(__name__)

HERE = Path(__file__).parent
PAGES = {"/": "live.html", "/live": "live.html", "/phone": "phone.html"}
STATUS_EVERY_S = 0.5  # phone seconds between status messages
MAX_GAP_S = 1.0  # a longer pause in the samples restarts the walker


@functools.cache
def _page(name: str) -> str:
    """The page ``name`` as served: read once, the stick-figure script inlined."""
    return inline_stickfigure((HERE / name).read_text("utf-8"))


def skeleton_message(method) -> dict:
    """What a viewer needs to draw the method's skeleton: ``parents``, ``sides``, the ``head``
    joint and the model's ``fps``, ``method`` and ``placements``."""
    from imuloco.viz.skeleton import joint_sides

    sk = method.skeleton_
    try:
        head = sk.part("head")
    except KeyError:
        head = sk.num_joints - 1
    return {"type": "skeleton", "parents": sk.parents.tolist(), "sides": joint_sides(sk),
            "head": int(head), "fps": float(method.fps_), "method": method.name,
            "placements": list(method.placements_)}


def parse_rows(message: str | bytes, width: int) -> np.ndarray:
    """The sample rows (N, width) of a phone message; ValueError naming what is wrong."""
    try:
        data = json.loads(message)
        rows = np.asarray(data["rows"], dtype=np.float64)
    except (ValueError, KeyError, TypeError) as e:
        raise ValueError(f"expected JSON {{\"rows\": [[t, acc x,y,z, gyro x,y,z], ...]}}: {e}"
                         ) from None
    if rows.ndim != 2 or rows.shape[1] != width:
        raise ValueError(f"expected rows of {width} numbers (time, then acc and gyro x, y, z "
                         f"per sensor), got an array of shape {rows.shape}")
    if not np.isfinite(rows).all():
        raise ValueError("rows hold non-finite values (NaN or infinity)")
    return rows


class LiveServer:
    """Routes phones, viewers and replays to :class:`LiveSession`\\ s.

    Parameters
    ----------
    method : a fitted online method (see :class:`LiveSession`).
    calibrate_s : seconds of samples used to calibrate the phone on the leg (0: none).
    note : where the model came from, shown to viewers.
    """

    def __init__(self, method, calibrate_s: float = 5.0, note: str = "",
                 height_m: float | None = None) -> None:
        probe = LiveSession(method, calibrate_s, height_m=height_m)  # fails early if offline
        self.height_m = height_m
        self.method = method
        self.calibrate_s = calibrate_s
        self.note = note
        self.viewers: set[ServerConnection] = set()
        self.phone: ServerConnection | None = None
        self.session: LiveSession | None = None
        self.server: Server | None = None
        self.status = "waiting for a phone"
        self.replaying = False
        delay_ms = probe.stream.delay_ms(method.fps_)
        if delay_ms:  # a model with look-ahead shows each pose that much after the step
            note = "; ".join(filter(None, [note, f"poses {delay_ms:.0f} ms late (look-ahead)"]))
        self._hello = dict(skeleton_message(method), note=note)
        self._last_status_t = -np.inf

    # ---- HTTP and websocket routing -----------------------------------------------------------
    def process_request(self, connection: ServerConnection, request: Request) -> Response | None:
        """Serve the pages over plain HTTP; let websocket upgrades through."""
        if request.headers.get("Upgrade", "").lower() == "websocket":
            return None
        page = PAGES.get(request.path.split("?", 1)[0])
        if page is None:
            return connection.respond(http.HTTPStatus.NOT_FOUND, "not found\n")
        response = connection.respond(http.HTTPStatus.OK, _page(page))
        del response.headers["Content-Type"]
        response.headers["Content-Type"] = "text/html; charset=utf-8"
        response.headers["Cache-Control"] = "no-store"
        return response

    async def handler(self, ws: ServerConnection) -> None:
        path = ws.request.path.split("?", 1)[0]
        if path == "/ws/view":
            await self._viewer(ws)
        elif path == "/ws/phone":
            await self._phone(ws)
        else:
            await ws.close(1008, f"unknown path {path}: use /ws/phone or /ws/view")

    async def _viewer(self, ws: ServerConnection) -> None:
        self.viewers.add(ws)
        try:
            await ws.send(json.dumps(self._hello))
            await ws.send(json.dumps({"type": "status", "text": self.status}))
            await ws.wait_closed()
        finally:
            self.viewers.discard(ws)

    async def _phone(self, ws: ServerConnection) -> None:
        if self.phone is not None or self.replaying:
            await ws.close(1013, "another phone is streaming" if self.phone is not None
                           else "the server is replaying a recording")
            return
        self.phone = ws
        self.start_session()
        width = 1 + 6 * len(self.method.placements_)
        try:
            async for message in ws:
                try:
                    rows = parse_rows(message, width)
                except ValueError as e:
                    await ws.send(json.dumps({"type": "error", "text": str(e)}))
                    continue
                self.feed(rows)
        except ConnectionClosed:
            pass
        finally:
            self.phone = None
            self.set_status("phone disconnected; waiting for a phone")

    # ---- the session --------------------------------------------------------------------------
    def publish(self, message: dict) -> None:
        broadcast(self.viewers, json.dumps(message, separators=(",", ":")))

    def set_status(self, text: str) -> None:
        """Tell the viewers and the phone."""
        self.status = text
        to = self.viewers | ({self.phone} if self.phone is not None else set())
        broadcast(to, json.dumps({"type": "status", "text": text}))

    def _status_due(self) -> bool:
        t = self.session.last_t if self.session and self.session.last_t is not None else 0.0
        if t - self._last_status_t < STATUS_EVERY_S:
            return False
        self._last_status_t = t
        return True

    def start_session(self, calibration=None) -> None:
        """A fresh session (frames from 0); ``calibration`` reuses a phone's mounting."""
        self.session = LiveSession(self.method, self.calibrate_s, calibration=calibration,
                                   height_m=self.height_m)
        self._last_status_t = -np.inf
        self.publish({"type": "reset"})
        self.set_status(self.session.describe())

    def feed(self, rows: np.ndarray) -> int:
        """Push sample rows (N, 1 + 6 S) into the session and broadcast the frames; returns
        how many frames came out. After a pause longer than ``MAX_GAP_S`` (the phone's page
        went to the background) the walker restarts, keeping the phone's calibration."""
        n = len(self.method.placements_)
        out = 0
        for row in rows:
            s = self.session
            if s.last_t is not None and row[0] - s.last_t > MAX_GAP_S:
                log.info("no samples for %.1f s: restarting the walker", row[0] - s.last_t)
                self.start_session(s.calibration)
                s = self.session
            chans = row[1:].reshape(n, 6)
            frames = s.push(float(row[0]), chans[:, :3], chans[:, 3:])
            if frames and frames[0].index == 0 and s.calibration is not None:
                c = s.calibration
                self.publish({"type": "calibrated", "rotations": c.rotations.tolist(),
                              "samples": c.samples, "seconds": round(c.seconds, 3),
                              "details": c.details})
            for msg in frames_to_json(frames):
                self.publish(msg)
            out += len(frames)
        text = self.session.describe()
        if self._status_due():
            self.set_status(text)
        else:
            self.status = text
        return out

    async def replay(self, path: str | Path, placement: str = "right_ankle", fmt: str = "auto",
                     speed: float = 1.0, loop: bool = False) -> None:
        """Stream a recorded log (any format :func:`imuloco.sensors.reallog.read_log` reads)
        at ``speed`` times real time, as a phone would."""
        from imuloco.sensors.reallog import read_log

        rec, _ = read_log(path, placement=placement, fmt=fmt, rate=None)
        rec = rec.select(self.method.placements_)
        rows = np.concatenate([rec.times[:, None], rec.channels()], axis=1)
        self.replaying = True
        try:
            await self._replay_rows(rows, speed, loop, Path(path).name)
        finally:
            self.replaying = False

    async def _replay_rows(self, rows: np.ndarray, speed: float, loop: bool, name: str) -> None:
        while True:
            self.start_session()
            start = time.perf_counter()
            i = 0
            while i < len(rows):
                due = start + (rows[i, 0] - rows[0, 0]) / speed
                delay = due - time.perf_counter()
                if delay > 0:
                    await asyncio.sleep(delay)
                now = (time.perf_counter() - start) * speed + rows[0, 0]
                j = max(i + 1, int(np.searchsorted(rows[:, 0], now, side="right")))
                self.feed(rows[i:j])
                i = j
            self.set_status(f"replay of {name} finished")
            if not loop:
                return

    # ---- running ------------------------------------------------------------------------------
    async def start(self, host: str = "127.0.0.1", port: int = 8765,
                    ssl: ssl_module.SSLContext | None = None) -> Server:
        """Start listening (``port=0`` picks a free port, see :attr:`port`)."""
        self.server = await serve(self.handler, host, port, process_request=self.process_request,
                                  ssl=ssl, compression=None, max_size=2**20)
        return self.server

    @property
    def port(self) -> int:
        return self.server.sockets[0].getsockname()[1]

    async def close(self) -> None:
        if self.server is not None:
            self.server.close()
            await self.server.wait_closed()


def ssl_context(certfile: str | Path, keyfile: str | Path | None = None) -> ssl_module.SSLContext:
    """A TLS server context from a certificate (PEM) and its key."""
    ctx = ssl_module.SSLContext(ssl_module.PROTOCOL_TLS_SERVER)
    ctx.load_cert_chain(certfile, keyfile)
    return ctx


async def run(server: LiveServer, host: str, port: int, ssl: ssl_module.SSLContext | None = None,
              replay: dict | None = None, on_start=None) -> None:
    """Serve until cancelled; with ``replay`` (keyword arguments of :meth:`LiveServer.replay`),
    stream that recording while serving. ``on_start(server)`` is called once listening."""
    await server.start(host, port, ssl)
    try:
        if on_start is not None:
            on_start(server)
        if replay is not None:
            await server.replay(**replay)
        await server.server.serve_forever()
    finally:
        await server.close()
