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
real time through the same path instead of a phone. The model runs in one worker thread, one
message at a time: the event loop keeps serving viewers while it works, and a phone is not
read further until its last message is done (back-pressure through TCP).

Access. Every address the server prints carries a per-session token (``?token=...``). Off
loopback the token is required for pages and websockets; on loopback it is checked when given.
A browser's ``Origin`` must be the server's own (the address the browser used) or one given in
``allow_origins``; on loopback the ``Host`` must be a loopback name (a page on another site that
re-resolves its name to 127.0.0.1, "DNS rebinding", is refused). The standard library-level
check (``serve(origins=...)``) takes a fixed list, while the server's own origin is whatever
address the phone used, hence the check here.

Limits (:class:`Limits`): bytes and rows per message, messages per second, phone seconds per
second, phone connections per client, viewers; rates are per client (address) and survive a
reconnect. Exceeding one closes that connection with a websocket close code and reason and
logs one line; so does a message that cannot be read at all (1007: JSON nested too deep, a
number beyond a float). Samples beyond the log readers' plausibility bounds are dropped with an
error message to the phone, the session goes on. A phone silent for ``phone_idle_s`` gives its
place to the next phone. A viewer too slow to read gets no poses until it catches up.

Browsers expose motion sensors to secure pages only: ``http://localhost`` is one, but a phone
reaching a laptop over the network needs HTTPS (``certfile``/``keyfile``, a self-signed
certificate will do once accepted on the phone).
"""

from __future__ import annotations

import asyncio
import functools
import http
import ipaddress
import json
import logging
import secrets
import ssl as ssl_module
import time
import traceback
from collections.abc import Iterable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import parse_qs, urlsplit

import numpy as np
from websockets.asyncio.server import Server, ServerConnection, broadcast, serve
from websockets.exceptions import ConnectionClosed
from websockets.http11 import Request, Response
from websockets.protocol import State

from imuloco.app.live.session import MAX_GAP_S, LiveSession, TokenBucket, frames_to_json
from imuloco.errors import FormatError, InputError
from imuloco.sensors.reallog import MAX_ABS_TIME, MAX_VALUE, read_log
from imuloco.viz.html import inline_stickfigure
from imuloco.viz.skeleton import joint_sides

log = logging.getLogger(__name__)

HERE = Path(__file__).parent
PAGES = {"/": "live.html", "/live": "live.html", "/phone": "phone.html"}
STATUS_EVERY_S = 0.5  # phone seconds between status messages
LOOPBACK_NAMES = ("localhost", "127.0.0.1", "::1")
LIMIT_CLOSE_TIMEOUT_S = 1.0  # closing a connection that broke a limit
YIELD_EVERY = 32  # messages broadcast between two returns to the event loop
MAX_CLIENTS = 1024  # clients (addresses) whose allowances are remembered; the least recent go
SINGLE_HEADERS = ("Host", "Origin", "Upgrade")  # read here: twice is a bad request


@functools.cache
def _page(name: str) -> str:
    """The page ``name`` as served: read once, the stick-figure script inlined."""
    return inline_stickfigure((HERE / name).read_text("utf-8"))


@dataclass(frozen=True)
class Limits:
    """What one client may do. Exceeding a limit closes the connection (code 1009 for a
    message too big, 1008 for a rate, 1013 for too many connections) with the reason.

    Rates are per client (its address), kept across its connections: reconnecting gives no
    fresh allowance, and a client may open at most ``phone_connect_burst`` phone connections
    at once, then ``phone_connects_per_s``. The idle rule: a phone that has sent nothing for
    ``phone_idle_s`` gives its place to the next phone that connects (closed with 1001)."""

    max_bytes: int = 256 * 1024  # one message (a phone sends ~75 bytes per row)
    max_rows: int = 1000  # sample rows in one message (10 s at 100 Hz)
    messages_per_s: float = 250.0  # per phone, after a burst of as many
    stream_speed: float = 2.0  # phone seconds per wall-clock second, after a burst of ...
    stream_burst_s: float = 30.0  # ... this many (a phone's backlog after a network stall)
    max_viewers: int = 200
    viewer_buffer: int = 256 * 1024  # bytes queued to a viewer before poses skip it
    phone_idle_s: float = 5.0  # a phone silent this long gives way to a new phone
    phone_connects_per_s: float = 0.2  # phone connections per client, after a burst of ...
    phone_connect_burst: int = 5  # ... this many (each starts a session: viewers see a reset)


class _BytesAfterRequest(logging.Filter):
    """websockets (17.4) logs "unexpected internal error" with an AssertionError's traceback
    (``send_eof``) when a client sends bytes after an HTTP request that is answered: it drops
    the connection, as it should; this turns the traceback into one line."""

    def filter(self, record: logging.LogRecord) -> bool:
        exc = record.exc_info[1] if record.exc_info else None
        if isinstance(exc, AssertionError) and exc.__traceback__ is not None \
                and traceback.extract_tb(exc.__traceback__)[-1].name == "send_eof":
            record.msg, record.args, record.exc_info = (
                "dropped a connection that sent bytes after its HTTP request", (), None)
            record.levelno, record.levelname = logging.WARNING, "WARNING"
        return True


_BYTES_AFTER_REQUEST = _BytesAfterRequest()


class LimitExceeded(Exception):
    """A connection broke a :class:`Limits` rule, or sent a message that cannot be read at all
    (1007: JSON nested too deep, a number beyond a float's range): close it with ``code`` and
    ``reason``."""

    def __init__(self, code: int, reason: str) -> None:
        super().__init__(reason)
        self.code, self.reason = code, reason


def skeleton_message(method) -> dict:
    """What a viewer needs to draw the method's skeleton: ``parents``, ``sides``, the ``head``
    joint and the model's ``fps``, ``method`` and ``placements``."""
    sk = method.skeleton_
    try:
        head = sk.part("head")
    except KeyError:
        head = sk.num_joints - 1
    return {"type": "skeleton", "parents": sk.parents.tolist(), "sides": joint_sides(sk),
            "head": int(head), "fps": float(method.fps_), "method": method.name,
            "placements": list(method.placements_)}


def parse_rows(message: str | bytes, width: int, max_rows: int | None = None) -> np.ndarray:
    """The sample rows (N, width) of a phone message; ValueError naming what is wrong,
    :class:`LimitExceeded` for more than ``max_rows`` rows."""
    try:
        data = json.loads(message)
        rows = data["rows"]
        if max_rows is not None and isinstance(rows, list) and len(rows) > max_rows:
            raise LimitExceeded(1009, f"{len(rows)} rows in one message; at most {max_rows}")
        rows = np.asarray(rows, dtype=np.float64)
    except RecursionError:
        raise LimitExceeded(1007, "JSON nested too deep: expected {\"rows\": [[t, ...], ...]}"
                            ) from None
    except OverflowError:
        raise LimitExceeded(1007, "a number beyond the range of a float") from None
    except (ValueError, KeyError, TypeError) as e:
        raise ValueError(f"expected JSON {{\"rows\": [[t, acc x,y,z, gyro x,y,z], ...]}}: {e}"
                         ) from None
    if rows.ndim != 2 or rows.shape[1] != width:
        raise ValueError(f"expected rows of {width} numbers (time, then acc and gyro x, y, z "
                         f"per sensor), got an array of shape {rows.shape}")
    if not np.isfinite(rows).all():
        raise ValueError("rows hold non-finite values (NaN or infinity)")
    return rows


def plausible(rows: np.ndarray, sensors: int) -> tuple[np.ndarray, str | None]:
    """The sample rows (N, 1 + 6 S) within the log readers' plausibility bounds
    (:data:`~imuloco.sensors.reallog.MAX_ABS_TIME` seconds,
    :data:`~imuloco.sensors.reallog.MAX_VALUE` per axis), and what was dropped (``None``:
    nothing). One sample at 1e200 would leave the model's state non-finite for good."""
    values = rows[:, 1:].reshape(len(rows), sensors, 2, 3)
    checks = [("time", np.abs(rows[:, 0]) > MAX_ABS_TIME, f"{MAX_ABS_TIME:g} s"),
              ("acc", (np.abs(values[:, :, 0]) > MAX_VALUE["acc"]).any(axis=(1, 2)),
               f"{MAX_VALUE['acc']:g} m/s^2"),
              ("gyro", (np.abs(values[:, :, 1]) > MAX_VALUE["gyro"]).any(axis=(1, 2)),
               f"{MAX_VALUE['gyro']:g} rad/s")]
    bad = np.logical_or.reduce([b for _, b, _ in checks])
    if not bad.any():
        return rows, None
    why = "; ".join(f"{q} beyond +-{limit}" for q, b, limit in checks if b.any())
    return rows[~bad], f"{int(bad.sum())} of {len(rows)} samples dropped: {why}"


def is_loopback(host: str) -> bool:
    """Whether binding ``host`` only listens on this machine."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _host_name(host_header: str) -> str:
    """``name`` of a Host header ``name[:port]`` or ``[v6]:port``, lower case."""
    h = host_header.strip().lower()
    if h.startswith("["):
        return h[1:h.find("]")] if "]" in h else h
    return h.rsplit(":", 1)[0] if h.count(":") == 1 else h


def _peer(ws: ServerConnection) -> str:
    addr = ws.remote_address
    return f"{addr[0]}:{addr[1]}" if addr else "?"


def _why_closed(ws: ServerConnection) -> str:
    """How the connection ended, as websockets words it (close codes sent and received)."""
    return str(ws.protocol.close_exc) if ws.protocol.state is State.CLOSED else "closing"


@dataclass
class _Batch:
    """What the worker made of some rows: frames reconstructed, and the messages for viewers
    as (type, JSON text) in order; the status line for viewers and the phone when due; what
    the phone is told of samples dropped."""

    frames: int
    messages: list[tuple[str, str]]
    status: str | None
    error: str | None = None


@dataclass
class _Client:
    """A client's allowances (token buckets), kept across its connections."""

    messages: TokenBucket
    stream: TokenBucket
    connects: TokenBucket


class LiveServer:
    """Routes phones, viewers and replays to :class:`LiveSession`\\ s.

    Parameters
    ----------
    method : a fitted online method (see :class:`LiveSession`).
    calibrate_s : seconds of samples used to calibrate the phone on the leg (0: none).
    note : where the model came from, shown to viewers.
    token : the session's access token (default: a fresh random one, see the module docstring).
    allow_origins : browser origins (``https://host:port``) allowed besides the server's own.
    limits : what one connection may do.
    require_token : whether a request without the token is refused (default: when
        :meth:`start` binds an address off loopback).
    height_m : the wearer's body height in metres: poses in their proportions (``None``: the
        model skeleton's).
    follow_path : the walker's root follows the path the sensor measures (see
        :class:`LiveSession`; its estimate on a thread of its own); False: the model's root.
    vmc : (host, port) of a VMC protocol receiver every frame is also sent to
        (:mod:`imuloco.app.live.vmc`; ``None``: none).
    fallback : the per-part fallback toward neutral poses (see :class:`LiveSession`;
        ``imuloco live --no-fallback``: off).
    """

    def __init__(self, method, calibrate_s: float = 5.0, note: str = "", token: str | None = None,
                 allow_origins: Iterable[str] = (), limits: Limits = Limits(),
                 require_token: bool | None = None, height_m: float | None = None,
                 follow_path: bool = True, vmc: tuple[str, int] | None = None,
                 fallback: bool = True) -> None:
        probe = LiveSession(method, calibrate_s, height_m=height_m,
                            follow_path=False)  # fails early: offline
        self.vmc = None
        if vmc is not None:  # python-osc (the [live] extra) is needed for --vmc only
            from imuloco.app.live.vmc import VmcSender

            self.vmc = VmcSender(probe.skeleton, method.fps_, *vmc)
        self.height_m = height_m
        self.follow_path = follow_path
        self.fallback = fallback
        self.method = method
        self.calibrate_s = calibrate_s
        self.note = note
        self.token = token or secrets.token_urlsafe(16)
        self.allow_origins = {o.rstrip("/").lower() for o in allow_origins}
        self.limits = limits
        self._require = require_token
        self.require_token = True if require_token is None else require_token
        self.loopback = False
        self.scheme = "http"
        self.viewers: set[ServerConnection] = set()
        self.skipped: dict[ServerConnection, int] = {}  # poses a slow viewer missed
        self.phone: ServerConnection | None = None
        self._phone_seen = 0.0  # time.monotonic() of the phone's last message or connection
        self._clients: dict[str, _Client] = {}  # by address, least recently seen first
        self._closing: set[asyncio.Task] = set()  # idle phones being closed
        self.session: LiveSession | None = None
        self.server: Server | None = None
        self.status = "waiting for a phone"
        self.replaying = False
        self._worker = ThreadPoolExecutor(1, thread_name_prefix="imuloco-live-model")
        delay_ms = probe.stream.delay_ms(method.fps_)
        if delay_ms:  # a model with look-ahead shows each pose that much after the step
            note = "; ".join(filter(None, [note, f"poses {delay_ms:.0f} ms late (look-ahead)"]))
        if height_m is not None:
            note = "; ".join(filter(None, [note, f"scaled to a {height_m:g} m tall walker"]))
        self._hello = json.dumps(dict(skeleton_message(method), note=note))
        self._last_status_t = -np.inf

    # ---- access -------------------------------------------------------------------------------
    def refusal(self, request: Request) -> str | None:
        """Why this request may not be served (token, Host, Origin), or None."""
        query = parse_qs(urlsplit(request.path).query)
        token = query.get("token", [None])[0]
        host = request.headers.get("Host", "")
        if self.loopback and _host_name(host) not in LOOPBACK_NAMES:
            return (f"Host {host!r} is not a loopback name: open the address `imuloco live` "
                    "printed")
        if token is None and self.require_token:
            return ("this server needs its token: open the address `imuloco live` printed "
                    "(it ends in ?token=...)")
        if token is not None and not secrets.compare_digest(token.encode(), self.token.encode()):
            return "wrong token: open the address `imuloco live` printed"
        origin = request.headers.get("Origin")
        if origin is not None:  # browsers send it; a page elsewhere must not reach in
            own = f"{self.scheme}://{host}".lower()
            if origin.rstrip("/").lower() not in self.allow_origins | {own}:
                return (f"Origin {origin!r} is not allowed (only {own}; start `imuloco live` "
                        "with --allow-origin to add one)")
        return None

    def urls(self, host: str) -> dict[str, str]:
        """The viewer's and the phone's address on ``host``, with the token."""
        base = f"{self.scheme}://{host}:{self.port}"
        return {name: f"{base}/{name}?token={self.token}" for name in ("live", "phone")}

    # ---- HTTP and websocket routing -----------------------------------------------------------
    def process_request(self, connection: ServerConnection, request: Request) -> Response | None:
        """Refuse what :meth:`refusal` names; serve the pages over plain HTTP; let websocket
        upgrades through."""
        twice = [h for h in SINGLE_HEADERS if len(request.headers.get_all(h)) > 1]
        if twice:
            log.warning("refused %s: more than one %s header", _peer(connection), twice[0])
            return connection.respond(http.HTTPStatus.BAD_REQUEST,
                                      f"more than one {twice[0]} header\n")
        why = self.refusal(request)
        if why is not None:
            log.warning("refused %s %s: %s", _peer(connection), urlsplit(request.path).path, why)
            return connection.respond(http.HTTPStatus.FORBIDDEN, why + "\n")
        if request.headers.get("Upgrade", "").lower() == "websocket":
            return None
        page = PAGES.get(urlsplit(request.path).path)
        if page is None:
            return connection.respond(http.HTTPStatus.NOT_FOUND, "not found\n")
        response = connection.respond(http.HTTPStatus.OK, _page(page))
        del response.headers["Content-Type"]
        response.headers["Content-Type"] = "text/html; charset=utf-8"
        response.headers["Cache-Control"] = "no-store"
        response.headers["Referrer-Policy"] = "no-referrer"  # the token stays in this tab
        return response

    async def handler(self, ws: ServerConnection) -> None:
        path = urlsplit(ws.request.path).path
        if path == "/ws/view":
            await self._viewer(ws)
        elif path == "/ws/phone":
            await self._phone(ws)
        else:
            await self._close(ws, "client", 1008, f"unknown path {path}: use /ws/phone or /ws/view")

    async def _close(self, ws: ServerConnection, who: str, code: int, reason: str) -> None:
        """Close with code and reason, logging one line."""
        log.warning("closing %s %s: %s", who, _peer(ws), reason)
        await ws.close(code, reason)

    async def _viewer(self, ws: ServerConnection) -> None:
        if len(self.viewers) >= self.limits.max_viewers:
            await self._close(ws, "viewer", 1013,
                              f"too many viewers (at most {self.limits.max_viewers})")
            return
        self.viewers.add(ws)
        self.skipped[ws] = 0
        try:
            await ws.send(self._hello)
            await ws.send(json.dumps({"type": "status", "text": self.status}))
            async for _ in ws:
                await self._close(ws, "viewer", 1008, "viewers only listen on /ws/view")
        except ConnectionClosed:
            pass
        finally:
            self.viewers.discard(ws)
            skipped = self.skipped.pop(ws, 0)
            late = f"; {skipped} poses skipped while it was slow" if skipped else ""
            if ws.protocol.close_rcvd is not None and ws.protocol.close_rcvd.code in (1000, 1001):
                log.info("viewer %s left%s", _peer(ws), late)
            else:  # dropped: one line, whatever was being sent to it
                log.warning("viewer %s dropped: %s%s", _peer(ws), _why_closed(ws), late)

    def _client(self, ws: ServerConnection) -> _Client:
        """The allowances of the client (address) behind ``ws``, fresh for a new one."""
        key = ws.remote_address[0] if ws.remote_address else "?"
        lim = self.limits
        client = self._clients.pop(key, None) or _Client(
            TokenBucket(lim.messages_per_s, lim.messages_per_s),
            TokenBucket(lim.stream_speed, lim.stream_burst_s),
            TokenBucket(lim.phone_connects_per_s, lim.phone_connect_burst))
        self._clients[key] = client  # now the most recent
        while len(self._clients) > MAX_CLIENTS:
            del self._clients[next(iter(self._clients))]
        return client

    def _give_way(self, now: float) -> bool:
        """Whether the phone slot is free for a new phone: none holds it, or the one that
        does has been idle for :attr:`Limits.phone_idle_s` (it is closed, 1001)."""
        idle = now - self._phone_seen
        if self.phone is None or idle < self.limits.phone_idle_s:
            return self.phone is None
        old = self.phone
        self._release(old)
        old.close_timeout = LIMIT_CLOSE_TIMEOUT_S
        task = asyncio.create_task(self._close(old, "phone", 1001, f"another phone took the "
                                                                   f"place after {idle:.1f} s idle"))
        self._closing.add(task)
        task.add_done_callback(self._closing.discard)
        return True

    async def _phone(self, ws: ServerConnection) -> None:
        now = time.monotonic()
        if self.replaying or not self._give_way(now):
            await self._close(ws, "phone", 1013, "the server is replaying a recording"
                              if self.replaying else "another phone is streaming")
            return
        lim = self.limits
        client = self._client(ws)
        if not client.connects.take(now):
            await self._close(ws, "phone", 1008, f"reconnecting too often (at most "
                                                 f"{lim.phone_connect_burst} at once, then "
                                                 f"{lim.phone_connects_per_s:g}/s)")
            return
        self.phone, self._phone_seen = ws, now
        self.start_session()
        refused = False
        try:
            async for message in ws:
                if self.phone is not ws:  # given way while idle: the session is another's
                    break
                self._phone_seen = time.monotonic()
                if not client.messages.take(self._phone_seen):
                    raise LimitExceeded(1008, f"more than {lim.messages_per_s:g} messages/s")
                try:
                    batch = await self._in_worker(self._message, message, client.stream)
                except ValueError as e:
                    await ws.send(json.dumps({"type": "error", "text": str(e)}))
                    continue
                await self._publish(batch)
                if batch.error is not None:
                    await ws.send(json.dumps({"type": "error", "text": batch.error}))
        except LimitExceeded as e:
            refused = True
            self._release(ws)  # at once: a phone reconnecting need not wait for the handshake
            # its unread messages stop this side reading, so its closing reply may never come:
            # drop the connection after a short wait instead of websockets' default 10 s
            ws.close_timeout = LIMIT_CLOSE_TIMEOUT_S
            await self._close(ws, "phone", e.code, e.reason)
        except ConnectionClosed:
            pass
        finally:
            if not refused:
                log.info("phone %s disconnected: %s", _peer(ws), _why_closed(ws))
            self._release(ws)

    def _release(self, ws: ServerConnection) -> None:
        """Free the phone slot if ``ws`` still holds it."""
        if self.phone is ws:
            self.phone = None
            self.set_status("phone disconnected; waiting for a phone")

    # ---- the session (process runs in the worker thread) ----------------------------------
    async def _in_worker(self, fn, *args):
        return await asyncio.get_running_loop().run_in_executor(self._worker, fn, *args)

    def _message(self, message: str | bytes, stream: TokenBucket) -> _Batch:
        """Parse and process one phone message within the limits (worker thread)."""
        sensors = len(self.method.placements_)
        rows, dropped = plausible(parse_rows(message, 1 + 6 * sensors, self.limits.max_rows),
                                  sensors)
        if not len(rows):
            return _Batch(0, [], None, dropped)
        last = self.session.last_t
        dt = np.diff(rows[:, 0], prepend=rows[0, 0] if last is None else last)
        seconds = float(dt[(dt > 0) & (dt <= MAX_GAP_S)].sum())  # a dropout costs nothing
        if not stream.take(time.monotonic(), seconds):
            raise LimitExceeded(1008, f"samples span more than {self.limits.stream_speed:g} s "
                                      "per second: stream in real time")
        batch = self.process(rows)
        batch.error = dropped
        return batch

    def process(self, rows: np.ndarray) -> _Batch:
        """Push sample rows (N, 1 + 6 S) into the session (no I/O: the worker runs this)."""
        n = len(self.method.placements_)
        s = self.session
        out, frames, dropouts = [], 0, s.dropouts
        for row in rows:
            chans = row[1:].reshape(n, 6)
            got = s.push(float(row[0]), chans[:, :3], chans[:, 3:])
            if got and got[0].index == 0 and s.calibration is not None:
                c = s.calibration
                out.append(("calibrated", json.dumps({
                    "type": "calibrated", "rotations": c.rotations.tolist(), "samples": c.samples,
                    "seconds": round(c.seconds, 3), "details": c.details})))
            out += [("pose", json.dumps(m, separators=(",", ":"))) for m in frames_to_json(got)]
            if self.vmc is not None:
                self.vmc.send(got)
            frames += len(got)
        if s.dropouts > dropouts:
            log.info("%d dropout(s) over %g s without samples: the model restarted, the walker "
                     "carries on", s.dropouts - dropouts, MAX_GAP_S)
        return _Batch(frames, out, s.describe() if self._status_due() else None)

    def feed(self, rows: np.ndarray) -> int:
        """:meth:`process` the rows here and broadcast at once; returns the frame count."""
        batch = self.process(rows)
        for kind, text in batch.messages:
            self._send(kind, text)
        self._status(batch)
        return batch.frames

    async def _publish(self, batch: _Batch) -> None:
        """Broadcast a batch, returning to the event loop every few messages."""
        for i, (kind, text) in enumerate(batch.messages):
            self._send(kind, text)
            if i % YIELD_EVERY == YIELD_EVERY - 1:
                await asyncio.sleep(0)
        self._status(batch)

    def _send(self, kind: str, text: str, to: Iterable[ServerConnection] | None = None) -> None:
        """Broadcast to viewers whose connection is still up (a connection lost but not yet
        noticed would log an asyncio warning per message); poses skip slow viewers."""
        targets = []
        for ws in self.viewers if to is None else to:
            if ws.transport.is_closing():
                continue
            if kind == "pose" and ws.transport.get_write_buffer_size() > self.limits.viewer_buffer:
                self.skipped[ws] = self.skipped.get(ws, 0) + 1
                continue
            targets.append(ws)
        broadcast(targets, text)

    def _status(self, batch: _Batch) -> None:
        if batch.status is not None:
            self.set_status(batch.status)
        else:
            self.status = self.session.describe()

    def publish(self, message: dict) -> None:
        self._send(message.get("type", ""), json.dumps(message, separators=(",", ":")))

    def set_status(self, text: str) -> None:
        """Tell the viewers and the phone (while calibrating, also ``calibrating``:
        ``{"seconds": held, "of": wanted}``, which their calibration screens draw)."""
        self.status = text
        to = self.viewers | ({self.phone} if self.phone is not None else set())
        message: dict = {"type": "status", "text": text}
        progress = self.session.calibration_progress() if self.session is not None else None
        if progress is not None:
            message["calibrating"] = {"seconds": round(progress[0], 2), "of": progress[1]}
        self._send("status", json.dumps(message), to)

    def _status_due(self) -> bool:
        t = self.session.last_t if self.session and self.session.last_t is not None else 0.0
        if t - self._last_status_t < STATUS_EVERY_S:
            return False
        self._last_status_t = t
        return True

    def start_session(self, calibration=None) -> None:
        """A fresh session (frames from 0); ``calibration`` reuses a phone's mounting."""
        if self.session is not None:
            self.session.close()
        self.session = LiveSession(self.method, self.calibrate_s, calibration=calibration,
                                   height_m=self.height_m, follow_path=self.follow_path,
                                   path_background=True, fallback=self.fallback)
        self._last_status_t = -np.inf
        self.publish({"type": "reset"})
        self.set_status(self.session.describe())

    async def replay(self, path: str | Path, placement: str = "right_ankle", fmt: str = "auto",
                     speed: float = 1.0, loop: bool = False) -> None:
        """Stream a recorded log (any format :func:`imuloco.sensors.reallog.read_log` reads)
        at ``speed`` times real time, as a phone would."""
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
                await self._publish(await self._in_worker(self.process, rows[i:j]))
                i = j
            self.set_status(f"replay of {name} finished")
            log.info("replay of %s finished%s", name, ", playing it again" if loop else
                     "; the viewer stays open (Ctrl-C stops)")
            if not loop:
                return

    # ---- running ------------------------------------------------------------------------------
    async def start(self, host: str = "127.0.0.1", port: int = 8765,
                    ssl: ssl_module.SSLContext | None = None) -> Server:
        """Start listening (``port=0`` picks a free port, see :attr:`port`)."""
        self.loopback = is_loopback(host)
        self.require_token = not self.loopback if self._require is None else self._require
        self.scheme = "https" if ssl else "http"
        logging.getLogger("websockets.server").addFilter(_BYTES_AFTER_REQUEST)
        try:
            self.server = await serve(self.handler, host, port,
                                      process_request=self.process_request, ssl=ssl,
                                      compression=None, max_size=self.limits.max_bytes)
        except OSError as e:  # an unknown host, a port in use or not allowed (--host, --port)
            raise InputError(f"cannot listen on {host}:{port}: {e.strerror or e}") from None
        return self.server

    @property
    def port(self) -> int:
        return self.server.sockets[0].getsockname()[1]

    async def close(self) -> None:
        if self.server is not None:
            self.server.close()
            await self.server.wait_closed()
        self._worker.shutdown(wait=True)
        if self.session is not None:
            self.session.close()
        if self.vmc is not None:
            self.vmc.close()


def ssl_context(certfile: str | Path, keyfile: str | Path | None = None) -> ssl_module.SSLContext:
    """A TLS server context from a certificate (PEM) and its key."""
    ctx = ssl_module.SSLContext(ssl_module.PROTOCOL_TLS_SERVER)
    try:
        ctx.load_cert_chain(certfile, keyfile)
    except ssl_module.SSLError as e:
        where = certfile if keyfile is None else f"{certfile} with key {keyfile}"
        raise FormatError(where, None, f"expected a PEM certificate and its private key "
                          f"({e.reason or e})") from None
    return ctx


def configure_logging() -> None:
    """One line per event on stderr: the server's own at INFO, websockets' own per-connection
    chatter off (a dropped viewer is one line of ours)."""
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s", datefmt="%H:%M:%S")
    logging.getLogger().setLevel(logging.INFO)  # also where a handler was there (the CLI's)
    logging.getLogger("websockets").setLevel(logging.WARNING)


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
