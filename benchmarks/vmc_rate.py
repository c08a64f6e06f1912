"""The VMC protocol output's rate and cost at real time (issue #44, "VMC over OSC").

    python benchmarks/vmc_rate.py [--seconds 60] [--log REC.csv] [--out docs/results/vmc]

Runs the command a user runs, ``imuloco live --replay REC --vmc 127.0.0.1:PORT --speed 1``
(the shipped model, the default 5 s calibration), in a child process, with a VMC receiver
(python-osc's ThreadingOSCUDPServer) on a free loopback port in this one; stops the child
(SIGTERM) after ``--seconds`` of replay. The recording: RealWorld's shin walk
(``../shared/data/realworld-shin``, a real phone at about 50 Hz) when present, else a
simulated walk of the bundled sample. Prints (and writes ``rate.json`` to ``--out``):
bundles received, the rate over the replay's duration and over the streaming after the
calibration, the calibration's burst, the gaps between bundles, and the sender's own cost
per bundle (building and sending one bundle, measured in this process).
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
from pythonosc.dispatcher import Dispatcher
from pythonosc.osc_packet import OscPacket
from pythonosc.osc_server import ThreadingOSCUDPServer

from imuloco.app.live.vmc import Bundles
from imuloco.data import shared_data_dir
from imuloco.io.atomic import atomic_write

CALIBRATE_S = 5.0  # the live command's default


class Arrivals(Dispatcher):
    """Each bundle's arrival (perf_counter) and its /VMC/Ext/T."""

    def __init__(self) -> None:
        super().__init__()
        self.lock, self.rows = threading.Lock(), []

    def call_handlers_for_packet(self, data, client_address):
        now = time.perf_counter()
        t = next((m.message.params[0] for m in OscPacket(data).messages
                  if m.message.address == "/VMC/Ext/T"), float("nan"))
        with self.lock:
            self.rows.append((now, t))
        return []


def recording(tmp: Path) -> Path:
    shared = shared_data_dir()
    shin = None if shared is None else shared.parent / "realworld-shin" / "acc_walking_shin.csv"
    if shin is not None and shin.is_file():
        return shin
    from imuloco.io.database import load_sample
    from imuloco.io.sensorlog import write_generic_csv
    from imuloco.sensors.simulate import simulate

    clip = max(load_sample().clips, key=lambda c: len(c.root) if "walk" in c.name else 0)
    return write_generic_csv(simulate(clip, ["right_ankle"], 100.0, "phone", 1),
                             tmp / "walk.csv")


def sender_cost(n: int = 300) -> float:
    """Milliseconds to turn one frame into a bundle and send it (to a closed port)."""
    from imuloco.app.live.session import Frame
    from imuloco.app.live.vmc import VmcSender
    from imuloco.app.pipeline import choose_model

    method = choose_model(None, None, "right_ankle").method
    sk = method.skeleton_
    rng = np.random.default_rng(0)
    rot = rng.normal(size=(n, sk.num_joints, 4))
    rot /= np.linalg.norm(rot, axis=-1, keepdims=True)
    frames = [Frame(k, k / 30, k / 30, rot[k], np.zeros(3), np.zeros((sk.num_joints, 3)))
              for k in range(n)]
    sender = VmcSender(sk, method.fps_, "127.0.0.1", 9)
    start = time.perf_counter()
    for f in frames:  # one at a time, as the live session hands them over
        sender.send([f])
    ms = (time.perf_counter() - start) / n * 1000
    sender.close()
    return ms


def fidelity(speed: float = 20.0) -> dict:
    """The receiver's rebuild against the reconstruction's BVH: a simulated walk of the
    bundled sample replayed in this process (the shipped model, ``speed`` times real time),
    each bundle's bones composed in Unity's axes (scipy), mirrored back, against the same
    reconstruction written as a BVH on the unity rig and read back."""
    import asyncio

    from scipy.spatial.transform import Rotation

    from imuloco.app.export import write_reconstruction
    from imuloco.app.live.server import LiveServer
    from imuloco.app.live.session import offline_frames
    from imuloco.app.pipeline import choose_model
    from imuloco.io.bvh import read_bvh
    from imuloco.io.database import load_sample
    from imuloco.io.sensorlog import write_generic_csv
    from imuloco.sensors.reallog import read_log
    from imuloco.sensors.simulate import simulate

    packets = Bundles()
    osc = ThreadingOSCUDPServer(("127.0.0.1", 0), packets)
    osc.socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
    threading.Thread(target=osc.serve_forever, daemon=True).start()
    method = choose_model(None, None, "right_ankle").method
    clip = next(c for c in load_sample().clips if c.name == "dataset-2_walk_exhausted_001")
    with tempfile.TemporaryDirectory() as tmp:
        path = write_generic_csv(simulate(clip, ["right_ankle"], 100.0, "phone", 5),
                                 Path(tmp) / "walk.csv")
        server = LiveServer(method, CALIBRATE_S, vmc=("127.0.0.1", osc.server_address[1]))
        asyncio.run(server.replay(path, speed=speed))
        asyncio.run(server.close())
        time.sleep(1.0)
        osc.shutdown()
        osc.server_close()
        rec, _ = read_log(path, rate=None)
        signals = offline_frames(rec.times, rec.acc, rec.gyro, method.fps_,
                                 server.session.calibration.rotations)
        ref = read_bvh(write_reconstruction(method.reconstruct_signals(signals),
                                            Path(tmp) / "ref.bvh", rig="unity"))
    names, parents = ref.skeleton.names, ref.skeleton.parents
    ref_pos = ref.positions()
    errors = []
    for messages in packets.packets:
        bones = {a[0]: a[1:] for addr, a in messages if addr == "/VMC/Ext/Bone/Pos"}
        root = next(a for addr, a in messages if addr == "/VMC/Ext/Root/Pos")
        t = next(a[0] for addr, a in messages if addr == "/VMC/Ext/T")
        pos, rot = np.empty((len(names), 3)), [None] * len(names)
        for j, name in enumerate(names):  # parents come first
            p_pos, p_rot = ((np.array(root[1:4]), Rotation.from_quat(root[4:8])) if
                            parents[j] < 0 else (pos[parents[j]], rot[parents[j]]))
            pos[j] = p_pos + p_rot.apply(bones[name][:3])
            rot[j] = p_rot * Rotation.from_quat(bones[name][3:7])
        errors.append(np.linalg.norm(pos * [-1.0, 1.0, 1.0] - ref_pos[round(t * method.fps_)],
                                     axis=1))
    errors = np.array(errors)
    return {"fidelity_clip": clip.name, "fidelity_bundles": len(errors),
            "fidelity_sent": server.vmc.sent,
            "rebuild_error_cm_mean": round(float(errors.mean()) * 100, 5),
            "rebuild_error_cm_max": round(float(errors.max()) * 100, 5)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=60.0, help="seconds of replay")
    ap.add_argument("--log", type=Path, default=None, help="recording (default: see above)")
    ap.add_argument("--out", type=Path, default=None, help="folder for rate.json")
    args = ap.parse_args()
    arrivals = Arrivals()
    osc = ThreadingOSCUDPServer(("127.0.0.1", 0), arrivals)
    osc.socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
    threading.Thread(target=osc.serve_forever, daemon=True).start()
    with tempfile.TemporaryDirectory() as tmp:
        log = args.log or recording(Path(tmp))
        cmd = [sys.executable, "-m", "imuloco.cli", "live", "--replay", str(log), "--port", "0",
               "--vmc", f"127.0.0.1:{osc.server_address[1]}", "--speed", "1"]
        child = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                 text=True)
        started = time.perf_counter()
        time.sleep(args.seconds)  # model loading comes first: the replay starts later
        while True:  # the replay's first --seconds: until a bundle shows that time
            with arrivals.lock:
                last_t = max((t for _, t in arrivals.rows), default=0.0)
            if last_t >= args.seconds - 1.0 or time.perf_counter() - started > 4 * args.seconds:
                break
            time.sleep(0.5)
        child.terminate()  # SIGTERM: a background job's children ignore SIGINT
        try:
            _, err = child.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            child.kill()
            _, err = child.communicate()
    osc.shutdown()
    osc.server_close()
    rows = np.array(arrivals.rows)
    if not len(rows):
        sys.exit(f"no bundle received; the command said:\n{err}")
    arrive, t = rows[:, 0], rows[:, 1]
    first = arrive[0]
    burst = int(np.sum(arrive - first < 0.05))  # the calibration's frames, sent at once
    steady = arrive[burst:]
    span_t = float(t.max())  # replay seconds covered (frame times from the first sample)
    gaps = np.diff(steady) * 1000
    result = {
        "recording": log.name, "speed": 1.0, "calibrate_s": CALIBRATE_S,
        "bundles": len(rows), "replay_seconds": round(span_t, 2),
        "bundles_per_s_over_replay": round(len(rows) / span_t, 2),
        "calibration_burst_bundles": burst,
        "bundles_per_s_streaming": round((len(steady) - 1) / float(steady[-1] - steady[0]), 2),
        # wall-clock seconds the streaming took per second of replay (1: real time kept)
        "wall_per_replay_second": round(float(steady[-1] - steady[0])
                                        / float(t[burst:].max() - t[burst:].min()), 3),
        "load_average_1min": round(os.getloadavg()[0], 1),
        "gap_ms_median": round(float(np.median(gaps)), 1),
        "gap_ms_p95": round(float(np.percentile(gaps, 95)), 1),
        "gap_ms_max": round(float(gaps.max()), 1),
        "out_of_order": int(np.sum(np.diff(t) < 0)),
        "sender_ms_per_bundle": round(sender_cost(), 3),
        **fidelity(),
        "python": sys.version.split()[0], "cpus": os.cpu_count(),
    }
    print(json.dumps(result, indent=1))
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        with atomic_write(args.out / "rate.json", "w") as f:
            f.write(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
