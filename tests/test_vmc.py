"""Live poses over the VMC protocol: axes, addresses, and a real OSC receiver on loopback that
rebuilds the skeleton from the messages and finds the reconstruction's joints."""

from __future__ import annotations

import asyncio
import socket
import threading
import time

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.spatial.transform import Rotation

from imuloco.cli import cli
from imuloco.errors import InputError
from imuloco.ops.rotations import qrot, to_matrix

pytest.importorskip("pythonosc")
from pythonosc.osc_server import ThreadingOSCUDPServer

from imuloco.app.live.vmc import (
    DEFAULT_PORT,
    Bundles,
    parse_address,
    to_unity_position,
    to_unity_rotation,
)

CLIP = "dataset-2_walk_normal_001"
CALIB_S = 4.0
# Unity's HumanBodyBones of the body (no fingers) and each one's parent in a Humanoid's
# hierarchy, nearest first (UpperChest is optional: Neck and the shoulders then hang on Chest),
# written out here from Unity's documentation, apart from the library's rig presets.
UNITY_PARENTS: dict[str, tuple[str, ...]] = {
    "Hips": (), "Spine": ("Hips",), "Chest": ("Spine",), "UpperChest": ("Chest",),
    "Neck": ("UpperChest", "Chest"), "Head": ("Neck",), "Jaw": ("Head",),
    **{f"{s}Eye": ("Head",) for s in ("Left", "Right")},
    **{f"{s}Shoulder": ("UpperChest", "Chest") for s in ("Left", "Right")},
    **{f"{s}UpperArm": (f"{s}Shoulder",) for s in ("Left", "Right")},
    **{f"{s}LowerArm": (f"{s}UpperArm",) for s in ("Left", "Right")},
    **{f"{s}Hand": (f"{s}LowerArm",) for s in ("Left", "Right")},
    **{f"{s}UpperLeg": ("Hips",) for s in ("Left", "Right")},
    **{f"{s}LowerLeg": (f"{s}UpperLeg",) for s in ("Left", "Right")},
    **{f"{s}Foot": (f"{s}LowerLeg",) for s in ("Left", "Right")},
    **{f"{s}Toes": (f"{s}Foot",) for s in ("Left", "Right")},
}


def test_unity_axes_are_the_mirror_image_and_rotations_follow():
    """A rotated vector in Unity's axes is the Unity rotation of the Unity vector, and the
    Unity rotation matrix is S R S (S = diag(-1, 1, 1)), for random rotations."""
    rng = np.random.default_rng(3)
    q = Rotation.random(200, random_state=4).as_quat()
    v = rng.normal(size=(200, 3))
    s = np.diag([-1.0, 1.0, 1.0])
    np.testing.assert_allclose(to_matrix(to_unity_rotation(q)), s @ to_matrix(q) @ s,
                               atol=1e-12)
    np.testing.assert_allclose(to_unity_position(qrot(q, v)),
                               qrot(to_unity_rotation(q), to_unity_position(v)), atol=1e-12)
    # a figure facing +Z: its left (imuloco's +X) is Unity's -X, as on a Unity Humanoid
    assert to_unity_position(np.array([1.0, 0.0, 0.0]))[0] == -1.0


@pytest.mark.parametrize(("text", "expected"), [
    ("127.0.0.1", ("127.0.0.1", DEFAULT_PORT)), ("studio.local:39540", ("studio.local", 39540)),
    ("[::1]:9000", ("::1", 9000)), ("::1", ("::1", DEFAULT_PORT)), ("[::1]", ("::1", 39539))])
def test_vmc_addresses_default_to_the_protocols_port(text, expected):
    assert parse_address(text) == expected


@pytest.mark.parametrize("text", ["host:abc", "host:0", "host:70000", ":39539", "", "[::1]x",
                                  "host:-1", "host:"])
def test_a_bad_vmc_address_is_one_error_line(text):
    with pytest.raises(InputError, match="--vmc"):
        parse_address(text)
    result = CliRunner().invoke(cli, ["live", "--vmc", text])
    assert result.exit_code == 1, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: --vmc"), result.output


def test_an_unknown_vmc_host_is_one_error_line(fitted):
    from imuloco.app.live.server import LiveServer

    with pytest.raises(InputError, match="cannot resolve 'no-such-host.invalid'"):
        LiveServer(fitted, vmc=("no-such-host.invalid", DEFAULT_PORT))


def _rebuild(messages: list[tuple[str, list]]) -> tuple[float, dict[str, np.ndarray]]:
    """What a receiver makes of one bundle: its /VMC/Ext/T and the world position of each
    bone, from the root and the bones' local positions and rotations composed in Unity's
    axes as Unity composes transforms, then mirrored back (x -> -x) to imuloco's."""
    by_address: dict[str, list] = {}
    bones = {}
    for address, args in messages:
        if address == "/VMC/Ext/Bone/Pos":
            bones[args[0]] = (np.array(args[1:4]), Rotation.from_quat(args[4:8]))
        else:
            by_address[address] = args
    assert by_address["/VMC/Ext/OK"] == [1]
    root = by_address["/VMC/Ext/Root/Pos"]
    assert root[0] == "root"
    world = {"root": (np.array(root[1:4]), Rotation.from_quat(root[4:8]))}
    out = {}

    def place(name: str) -> tuple[np.ndarray, Rotation]:
        if name not in world:
            parent = next((p for p in UNITY_PARENTS[name] if p in bones), "root")
            p_pos, p_rot = place(parent)
            pos, rot = bones[name]
            world[name] = (p_pos + p_rot.apply(pos), p_rot * rot)
        return world[name]

    for name in bones:
        out[name] = place(name)[0] * [-1.0, 1.0, 1.0]
    return by_address["/VMC/Ext/T"][0], out


@pytest.fixture(scope="module")
def fitted(ridge_without_demo_clip):
    return ridge_without_demo_clip


@pytest.fixture(scope="module")
def received(fitted, sample_db, tmp_path_factory):
    """A recorded walk replayed by the live server with a VMC receiver on loopback: the
    server, the bundles' messages, the recording's path."""
    from imuloco.app.live.server import LiveServer
    from imuloco.io.sensorlog import write_generic_csv
    from imuloco.sensors.simulate import simulate

    clip = next(c for c in sample_db.clips if c.name == CLIP)
    path = write_generic_csv(simulate(clip, ["right_ankle"], 100.0, "phone", 12),
                             tmp_path_factory.mktemp("vmc") / "walk.csv")
    packets = Bundles()
    osc = ThreadingOSCUDPServer(("127.0.0.1", 0), packets)
    # the calibration's frames come out at once when it ends: room for that burst
    osc.socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
    thread = threading.Thread(target=osc.serve_forever, daemon=True)
    thread.start()
    # the model's own root (follow_path=False): compared with the offline reconstruction below
    server = LiveServer(fitted, calibrate_s=CALIB_S, fallback=False,  # offline is the model's
                        vmc=("127.0.0.1", osc.server_address[1]),
                        follow_path=False)
    try:
        asyncio.run(asyncio.wait_for(server.replay(path, speed=25.0), 60))
        for _ in range(100):  # until the receiver has them all (or 2 s)
            with packets.lock:
                if len(packets.packets) >= server.vmc.sent:
                    break
            time.sleep(0.02)
    finally:
        asyncio.run(server.close())
        osc.shutdown()
        osc.server_close()
    return server, packets.packets, path


def test_vmc_bundles_carry_unity_bones_unit_quaternions_at_the_pose_rate(received, fitted):
    from imuloco.sensors.reallog import read_log

    server, packets, path = received
    assert server.vmc.dropped == 0 and len(packets) == server.vmc.sent > 0
    times = []
    for messages in packets:
        addresses = [a for a, _ in messages]
        assert addresses[0] == "/VMC/Ext/Root/Pos" and addresses[-2:] == ["/VMC/Ext/OK",
                                                                          "/VMC/Ext/T"]
        names = [args[0] for a, args in messages if a == "/VMC/Ext/Bone/Pos"]
        assert set(names) <= set(UNITY_PARENTS) and len(names) == len(set(names)) == 21
        local = {args[0]: np.array(args[1:4]) for a, args in messages if a == "/VMC/Ext/Bone/Pos"}
        # Unity's axes: a Humanoid faces +Z with its left at -X
        assert local["LeftUpperLeg"][0] < 0 < local["RightUpperLeg"][0]
        assert local["LeftShoulder"][0] < 0 < local["RightShoulder"][0]
        assert local["LeftToes"][2] > 0 and local["LeftLowerArm"][0] < -0.2
        quats = np.array([args[4:8] for _, args in messages[:-2]])
        np.testing.assert_allclose(np.linalg.norm(quats, axis=1), 1.0, atol=1e-6)
        times.append(messages[-1][1][0])
    # one bundle per model frame, every frame of the replay (the frames' /VMC/Ext/T)
    frames = np.round(np.sort(times) * fitted.fps_).astype(int)
    np.testing.assert_array_equal(frames, np.arange(len(frames)))
    rec, _ = read_log(path, rate=None)
    seconds = rec.times[-1] - rec.times[0]
    assert len(packets) / seconds >= 25.0, f"{len(packets)} bundles over {seconds:.1f} s"


def test_the_skeleton_rebuilt_from_vmc_matches_the_reconstructions_bvh(received, fitted,
                                                                       tmp_path):
    """The receiver's forward kinematics of the messages lands on the joints of the same
    reconstruction written as a BVH (unity rig) and read back: within 1 cm."""
    from imuloco.app.export import write_reconstruction
    from imuloco.app.live.session import offline_frames
    from imuloco.io.bvh import read_bvh
    from imuloco.sensors.reallog import read_log

    server, packets, path = received
    rec, _ = read_log(path, rate=None)
    signals = offline_frames(rec.times, rec.acc, rec.gyro, fitted.fps_,
                             server.session.calibration.rotations)
    bvh = write_reconstruction(fitted.reconstruct_signals(signals), tmp_path / "ref.bvh",
                               rig="unity")
    ref = read_bvh(bvh)
    ref_pos, names = ref.positions(), ref.skeleton.names
    worst = 0.0
    for messages in packets:
        t, rebuilt = _rebuild(messages)
        k = round(t * fitted.fps_)
        assert set(rebuilt) == set(names)
        got = np.array([rebuilt[n] for n in names])
        worst = max(worst, float(np.abs(got - ref_pos[k]).max()))
    assert worst < 0.01, f"{worst * 100:.2f} cm"
    # the figure stands up and walks: the head above the feet, the root moving
    head = ref_pos[:, names.index("Head"), 1]
    assert np.all(head - ref_pos[:, names.index("LeftFoot"), 1] > 1.0)


def test_a_network_refusal_drops_the_bundle_and_the_session_goes_on(received, fitted,
                                                                   caplog):
    from imuloco.app.live.session import Frame
    from imuloco.app.live.vmc import VmcSender

    sender = VmcSender(received[0].session.skeleton, fitted.fps_, "127.0.0.1", 9)
    sender.socket.close()

    class Full:
        def sendto(self, data, address):
            raise BlockingIOError(11, "Resource temporarily unavailable")

    sender.socket = Full()
    rest = np.tile([0.0, 0.0, 0.0, 1.0], (21, 1))
    frames = [Frame(k, k / 30, k / 30, rest, np.zeros(3), np.zeros((21, 3))) for k in range(3)]
    assert sender.send(frames) == 0
    assert sender.dropped == 3 and sender.sent == 0
    assert sum("dropped" in r.getMessage() for r in caplog.records) == 1


def test_the_senders_frames_are_the_unity_rig_presets(fitted, sample_db):
    """Frame by frame, the sender's motion is :func:`apply_rig`'s on the unity preset (names,
    offsets, rotations) with the sample's T-pose rest."""
    from imuloco.app.export import rest_of
    from imuloco.app.live.session import Frame
    from imuloco.app.live.vmc import VmcSender
    from imuloco.core.rigs import apply_rig

    clip = next(c for c in sample_db.clips if c.name == CLIP)
    sender = VmcSender(clip.skeleton, clip.fps, "127.0.0.1", DEFAULT_PORT)
    frames = [Frame(k, k / clip.fps, 0.0, clip.rotations[k], clip.root[k],
                    np.zeros((clip.skeleton.num_joints, 3))) for k in range(0, 60, 7)]
    got = sender.motion(frames)
    sender.close()
    want = apply_rig(clip, "unity", rest_of(clip))
    assert got.skeleton.names == want.skeleton.names
    np.testing.assert_allclose(got.skeleton.offsets, want.skeleton.offsets, atol=1e-12)
    np.testing.assert_allclose(got.rotations, want.rotations[0:60:7], atol=1e-12)
    np.testing.assert_allclose(got.positions(), clip.positions()[0:60:7], atol=1e-9)


def test_live_replay_sends_vmc_from_the_command_line(monkeypatch, fitted, received):
    """``imuloco live --replay REC --vmc 127.0.0.1:PORT``: the command says where it sends,
    and the receiver gets a bundle per frame (the server's run is the real one up to serving
    forever, which this test skips: it replays, then stops)."""
    from imuloco.app import pipeline
    from imuloco.app.live import server as live_server
    from imuloco.app.pipeline import ModelChoice

    async def replay_then_stop(server, host, port, ssl, replay, on_start):
        await server.start("127.0.0.1", 0, ssl)
        try:
            on_start(server)
            await server.replay(**replay)
        finally:
            await server.close()
        sent.append(server.vmc.sent)

    sent: list[int] = []
    monkeypatch.setattr(live_server, "run", replay_then_stop)
    monkeypatch.setattr(live_server, "configure_logging", lambda: None)
    monkeypatch.setattr(pipeline, "choose_model", lambda *a, **k: ModelChoice(
        fitted, "given", "ridge"))
    packets = Bundles()
    osc = ThreadingOSCUDPServer(("127.0.0.1", 0), packets)
    osc.socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
    threading.Thread(target=osc.serve_forever, daemon=True).start()
    try:
        result = CliRunner().invoke(cli, [
            "live", "--replay", str(received[2]), "--speed", "25", "--calibrate-seconds",
            str(CALIB_S), "--vmc", f"127.0.0.1:{osc.server_address[1]}"])
        for _ in range(100):
            if sent and len(packets.packets) >= sent[0]:
                break
            time.sleep(0.02)
    finally:
        osc.shutdown()
        osc.server_close()
    assert result.exit_code == 0, result.output
    assert f"vmc:    sending poses to 127.0.0.1:{osc.server_address[1]}" in result.output
    assert len(packets.packets) == sent[0] == len(received[1])
