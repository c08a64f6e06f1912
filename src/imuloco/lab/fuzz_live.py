"""The ``live`` reader kind of ``imuloco bench --fuzz`` (issue 42, items 16-18): what a phone or
a browser sends the live server, played against a fresh :class:`~imuloco.app.live.server.
LiveServer` on 127.0.0.1 per input (loopback only; every connection and wait is bounded).

A case's files are what is sent, in name order: ``request.http`` (raw bytes of one HTTP
request) or ``cK-mNNN.msg`` (message NNN of phone connection K; connections one after
another). Seeds (:func:`live_seeds`): a valid upgrade request, and a walk's rows as a few
messages. The structured attacks (:func:`live_attack`): JSON nested 100,000 deep, a 400-digit
integer, times of +-1e308, values of 1e200 for half a second, NaN/strings/ragged rows, a flood
of one-row messages, reconnecting 8 times, and requests with a Host, Origin or Upgrade
header twice, a header line without a colon or a 60 KiB header.

:func:`play` judges the server, not the client: a traceback in its log or a close with 1011
is a foreign exception (raised as such); a close with a code and a reason, an HTTP 4xx or an
error message to the phone is a clean refusal (raised as the library's error naming the case);
:func:`live_garbage` adds what may not be accepted: samples beyond the log readers' bounds
taken without an error to the phone, a session that cannot reconstruct valid samples after the
case (poisoned), more sessions started (viewer resets)
than :attr:`~imuloco.app.live.server.Limits.phone_connect_burst`, and an HTTP 5xx.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import json
import logging
import random
from pathlib import Path

import numpy as np

from imuloco.errors import InputError
from imuloco.io.database import load_sample
from imuloco.lab.mutations import Files
from imuloco.methods import get_method
from imuloco.sensors.reallog import MAX_ABS_TIME, MAX_VALUE

KINDS = ("deep", "huge-int", "huge-time", "huge-values", "rows", "flood", "reconnect",
         "headers")
FLOOD = 300  # one-row messages sent as fast as possible (the default limit: 250 a second)
RECONNECTS = 8  # more than Limits.phone_connect_burst, few enough for the 5 s per input
WAIT_S = 1.0  # the longest wait for one answer of the server
END = "end of case"  # the last message of each connection: its error says all came through


def live_seeds(times: np.ndarray, acc: np.ndarray, gyro: np.ndarray) -> list[Files]:
    """A valid websocket upgrade request and a walk's rows (N, 7) in messages of 50 rows."""
    rows = np.c_[times, acc, gyro][:200]
    msgs = {f"c0-m{k:03d}.msg": json.dumps({"rows": rows[i:i + 50].round(6).tolist()}).encode()
            for k, i in enumerate(range(0, len(rows), 50))}
    return [{"request.http": _request()}, msgs]


def _request(extra: str = "") -> bytes:
    return ("GET /ws/phone HTTP/1.1\r\nHost: 127.0.0.1:PORT\r\nUpgrade: websocket\r\n"
            "Connection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
            f"Sec-WebSocket-Version: 13\r\n{extra}\r\n").encode()


def live_attack(files: Files, rng: random.Random) -> tuple[str, Files]:
    """One structured attack (module docstring)."""
    kind = rng.choice(KINDS)
    if kind == "headers":
        extra = rng.choice(("Host: 127.0.0.1:PORT\r\n", "Host: evil.example\r\n",
                            "Origin: http://127.0.0.1:PORT\r\nOrigin: http://evil.example\r\n",
                            "Upgrade: websocket\r\n", "Origin: null\r\nOrigin: null\r\n",
                            "X-Colonless\r\n", "X-Big: " + "a" * 60_000 + "\r\n"))
        return f"attack:headers-{extra.split(':')[0].split(chr(13))[0]}", {
            "request.http": _request(extra)}
    msgs = [json.loads(v) for k, v in sorted(files.items()) if k.endswith(".msg")]
    if not msgs:  # the request seed: attack a walk instead
        msgs = [{"rows": [[0.01 * i, 0.0, 9.81, 0.0, 0.1, 0.0, 0.0] for i in range(200)]}]
    rows = np.array([r for m in msgs for r in m["rows"]])
    t_end = float(rows[-1, 0])
    out = [json.dumps({"rows": rows[:100].tolist()})]
    if kind == "deep":
        depth = rng.choice((1_000, 100_000))
        out.append(rng.choice(("[" * depth + "]" * depth,
                               '{"rows": ' + "[" * depth + "]" * depth + "}")))
    elif kind == "huge-int":
        out.append('{"rows": [[' + "9" * rng.choice((310, 400, 4000)) + ", 0, 9.81, 0, 0, 0, 0]]}")
    elif kind == "huge-time":
        bad = rows[100:110].copy()
        bad[:, 0] = rng.choice((1e308, -1e308, 1e14, 5e-324))
        out.append(json.dumps({"rows": bad.tolist()}))
    elif kind == "huge-values":
        bad = rows[100:150].copy()
        bad[:, rng.randrange(1, 7)] = rng.choice((1e200, -1e200, 1e5, 1e308))
        out.append(json.dumps({"rows": bad.tolist()}))
    elif kind == "rows":
        out.append(rng.choice(('{"rows": [[NaN, 0, 0, 0, 0, 0, 0]]}', '{"rows": [["1"]]}',
                               '{"rows": [[1, 2], [3]]}', '{"rows": 5}', '"rows"', "[]",
                               '{"rows": [[1e999, 0, 0, 0, 0, 0, 0]]}', "\x00" * 10)))
    elif kind == "flood":
        out += [json.dumps({"rows": [[t_end + 1e-3 * (k + 1), 0, 9.81, 0, 0, 0, 0]]})
                for k in range(FLOOD)]
    if kind == "reconnect":
        return f"attack:{kind}", {f"c{c:02d}-m000.msg": out[0].encode()
                                  for c in range(RECONNECTS)}
    return f"attack:{kind}", {f"c0-m{k:03d}.msg": m.encode() for k, m in enumerate(out)}


# ---------------------------------------------------------------------------------------------
# playing a case against a server (in the fuzz worker)

@functools.cache
def live_method():
    """The online method the server runs: ridge fitted on two sample clips (cached)."""
    return get_method("ridge").fit(load_sample().subset([0, 1]), ["right_ankle"], "phone", 0)


class _Log(logging.Handler):
    """The server's log records that are tracebacks or errors."""

    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.bad: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        if record.exc_info or record.levelno >= logging.ERROR:
            self.bad.append(f"{record.name}: {record.getMessage()}"
                            + (f" ({record.exc_info[0].__name__})" if record.exc_info else ""))


def play(paths: list[Path]) -> dict:
    """Send the case to a fresh server; what the server did (see :func:`live_garbage`)."""
    handler = _Log()
    loggers = [logging.getLogger(n) for n in ("websockets", "imuloco", "asyncio")]
    logging.disable(logging.NOTSET)  # the fuzz worker silences logging: the log is the oracle
    for lg in loggers:
        lg.addHandler(handler)
    try:
        found = asyncio.run(_play(paths))
    finally:
        for lg in loggers:
            lg.removeHandler(handler)
        logging.disable(logging.CRITICAL)
    if handler.bad or 1011 in found["codes"]:
        raise RuntimeError(f"server: {(handler.bad or ['closed 1011'])[0]}"[:200])
    if found["refused"] and found["problem"] is None:
        raise InputError(f"{paths[0].name}: refused: {found['refused'][0]}"[:200])
    return found


async def _play(paths: list[Path]) -> dict:
    # the [live] extra's (websockets): lab.fuzz imports this module for every reader
    from imuloco.app.live.server import LiveServer

    server = LiveServer(live_method(), calibrate_s=0)
    sessions = 0
    start = server.start_session

    def counted(*args, **kwargs):
        nonlocal sessions
        sessions += 1
        return start(*args, **kwargs)

    server.start_session = counted
    await server.start("127.0.0.1", 0)
    found = {"codes": [], "refused": [], "problem": None}
    try:
        if paths[0].name == "request.http":
            await _http(server, paths[0].read_bytes(), found)
        else:
            await _phones(server, paths, found)
            if sessions > getattr(server.limits, "phone_connect_burst", 5):  # 5 before its time
                found["problem"] = f"{sessions} sessions started (viewer resets)"
            if found["problem"] is None and server.session is not None:
                for _ in range(100):  # the phone's handler done with its messages
                    if server.phone is None:
                        break
                    await asyncio.sleep(0.02)
                found["problem"] = await server._in_worker(_poisoned, server)
    finally:
        await server.close()
    return found


async def _http(server, request: bytes, found: dict) -> None:
    reader, writer = await asyncio.open_connection("127.0.0.1", server.port)
    try:
        writer.write(request.replace(b"PORT", str(server.port).encode()))
        await writer.drain()
        with contextlib.suppress(asyncio.TimeoutError, ConnectionError):
            status = (await asyncio.wait_for(reader.readline(), WAIT_S)).decode("latin-1")
            code = status.split(" ")[1] if status.count(" ") >= 2 else ""
            if code.startswith("5"):
                found["problem"] = f"HTTP {status.strip()}"
            elif code != "101":
                found["refused"].append(status.strip())
    finally:
        writer.close()


async def _phones(server, paths: list[Path], found: dict) -> None:
    from websockets.asyncio.client import connect  # the [live] extra's
    from websockets.exceptions import ConnectionClosed

    connections: dict[str, list[bytes]] = {}
    for p in sorted(paths):
        connections.setdefault(p.name.split("-")[0], []).append(p.read_bytes())
    for messages in connections.values():
        async with connect(f"ws://127.0.0.1:{server.port}/ws/phone", max_size=None,
                           open_timeout=2 * WAIT_S, close_timeout=WAIT_S) as ws:
            try:
                for m in messages:
                    await ws.send(m.decode("utf-8", "replace"))
                await ws.send(json.dumps({"rows": END}))
                dropped = await _answers(ws, found)
            except ConnectionClosed:
                dropped = None
            except Exception as e:  # noqa: BLE001 - the client's own failure (a 10 MB send
                # as the server closes): the server is judged by its log and close codes
                dropped = None
                found["refused"].append(f"client: {type(e).__name__}")
            if ws.close_code is not None:
                found["codes"].append(ws.close_code)
                found["refused"].append(f"closed {ws.close_code} {ws.close_reason}")
            elif dropped is not None and dropped < sum(map(_implausible, messages)):
                found["problem"] = "samples beyond the readers' bounds taken without a word"


async def _answers(ws, found: dict) -> int | None:
    """Read what the server says until its answer to the :data:`END` message (or a close);
    how many messages it said it dropped samples of (None: no answer to END in time)."""
    dropped = 0
    with contextlib.suppress(asyncio.TimeoutError):
        while True:
            msg = json.loads(await asyncio.wait_for(ws.recv(), 2 * WAIT_S))
            if msg.get("type") == "error":
                if END in msg.get("text", ""):
                    return dropped
                dropped += "samples dropped" in msg.get("text", "")
                found["refused"].append(f"error: {msg.get('text', '')}"[:150])
    return None


def _implausible(message: bytes) -> bool:
    """Whether a message's rows (if it has rows of 7 numbers) hold a sample beyond the log
    readers' bounds (:data:`~imuloco.sensors.reallog.MAX_ABS_TIME`, ``MAX_VALUE``)."""
    try:
        rows = np.asarray(json.loads(message)["rows"], dtype=np.float64)
    except (ValueError, KeyError, TypeError, OverflowError, RecursionError):
        return False
    if rows.ndim != 2 or rows.shape[1] != 7 or not len(rows) or not np.isfinite(rows).all():
        return False
    return bool((np.abs(rows[:, 0]) > MAX_ABS_TIME).any()
                or (np.abs(rows[:, 1:4]) > MAX_VALUE["acc"]).any()
                or (np.abs(rows[:, 4:7]) > MAX_VALUE["gyro"]).any())


def _poisoned(server) -> str | None:
    """Why the session cannot go on after the case: a second of valid walking samples after
    its last one does not give finite poses (run in the server's model thread)."""
    s = server.session
    t0 = (s.last_t or 0.0) + 0.01
    t = t0 + np.arange(100) * 0.01
    rows = np.c_[t, np.sin(t), 9.81 + np.cos(t), 0 * t, 3 * np.cos(5 * t), 0 * t, 0 * t]
    try:
        batch = server.process(rows)
    except Exception as e:  # noqa: BLE001 - any failure is the verdict
        return f"poisoned: {type(e).__name__}: {e}"[:200]
    poses = [json.loads(text) for kind, text in batch.messages if kind == "pose"]
    if not poses and t[-1] > t0 + 0.5 and s.last_t == t[-1]:
        return "poisoned: no poses from a second of samples"
    if not all(np.isfinite(p["positions"]).all() for p in poses if p["positions"]):
        return "poisoned: non-finite poses"
    return None


def live_garbage(found: dict) -> str | None:
    """What the server accepted that it may not (module docstring), or None."""
    return found["problem"]
