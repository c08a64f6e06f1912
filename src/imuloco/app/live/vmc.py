"""Live poses out over the VMC protocol (OSC over UDP), for VSeeFace, VMC4B (Blender), EVMC4U
(Unity), VMC4UE (Unreal) and other "Marionette" receivers (``imuloco live --vmc HOST:PORT``).

One OSC bundle per reconstructed frame, at the pose rate, as a VMC "Performer" sends it
(protocol.vmc.info, english spec): ``/VMC/Ext/Root/Pos "root" p.xyz q.xyzw``, one
``/VMC/Ext/Bone/Pos NAME p.xyz q.xyzw`` per joint, ``/VMC/Ext/OK 1`` and ``/VMC/Ext/T time``.

- Names, hierarchy and rest: the ``unity`` rig preset (:mod:`imuloco.core.rigs`): Unity's
  HumanBodyBones names (``Hips``, ``Spine``, ``Chest``, ``Neck``, ``Head``, ``LeftShoulder``,
  ``LeftUpperArm`` ... ``LeftToes``; the model has no ``UpperChest``, which Unity's Humanoid
  leaves optional), re-expressed on a T-pose rest whose joint frames are the world's, as a
  normalised VRM avatar's are: a zero local rotation is the T-pose, facing +Z.
- Bone messages carry the bone's position and rotation local to its parent bone (Unity's
  ``localPosition``/``localRotation``): the rest bone vector and the preset's local rotation.
- The root message carries the model's root on the floor: the hips' ground point (x, 0, z),
  no rotation; ``Hips`` carries the hips' height above it and the body's rotation. A receiver
  that only applies rotations (EVMC4U without bone position sync) still walks the avatar.
- Axes: Unity's are left-handed (X right, Y up, Z forward; metres); imuloco's right-handed
  with the body's left along +X when it faces +Z. The change is the mirror ``x -> -x``
  (:func:`to_unity_position`); a rotation ``R`` becomes ``S R S`` (``S = diag(-1, 1, 1)``),
  whose quaternion is ``(x, -y, -z, w)`` (:func:`to_unity_rotation`): the axis of a rotation
  is a pseudovector, mirrored and negated.
- ``/VMC/Ext/T``: the frame's time in seconds since the session's first sample.

UDP does not block and does not tell: a bundle the network refuses at once (buffer full,
no route) is dropped and counted (:attr:`VmcSender.dropped`), never raised into the session.
"""

from __future__ import annotations

import logging
import socket
import threading
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
from pythonosc.dispatcher import Dispatcher
from pythonosc.osc_message_builder import OscMessageBuilder
from pythonosc.osc_packet import OscPacket
from pythonosc.parsing import osc_types
from pythonosc.parsing.osc_types import IMMEDIATELY

from imuloco.app.export import sample_rest
from imuloco.core.motion import Motion
from imuloco.core.rigs import apply_rig
from imuloco.core.skeleton import Skeleton
from imuloco.errors import InputError
from imuloco.ops.restpose import rebase_rotations

if TYPE_CHECKING:
    from imuloco.app.live.session import Frame

log = logging.getLogger(__name__)

DEFAULT_PORT = 39539  # the VMC protocol's Marionette (receiver) port
RIG = "unity"  # the rig preset whose names and rest the messages carry
_MIRROR = np.array([-1.0, 1.0, 1.0])
_MIRROR_Q = np.array([1.0, -1.0, -1.0, 1.0])


def to_unity_position(p: np.ndarray) -> np.ndarray:
    """Positions (..., 3) from imuloco's right-handed Y-up axes to Unity's left-handed ones."""
    return np.asarray(p, dtype=np.float64) * _MIRROR


def to_unity_rotation(q: np.ndarray) -> np.ndarray:
    """Quaternions (..., 4) x, y, z, w from imuloco's axes to Unity's (see the module)."""
    return np.asarray(q, dtype=np.float64) * _MIRROR_Q


def parse_address(text: str) -> tuple[str, int]:
    """``HOST``, ``HOST:PORT`` or ``[IPv6]:PORT`` as (host, port); the port defaults to
    :data:`DEFAULT_PORT`. :class:`InputError` naming ``--vmc`` and what was expected."""
    expected = f"expected HOST or HOST:PORT (port 1-65535, default {DEFAULT_PORT})"
    text = text.strip()
    if text.startswith("["):  # [v6] or [v6]:port
        host, _, rest = text[1:].partition("]")
        port = rest[1:] if rest.startswith(":") else None if not rest else "?"
    elif text.count(":") == 1:
        host, port = text.split(":")
    else:  # a name, an IPv4 address or a bare IPv6 address
        host, port = text, None
    if not host or port == "?":
        raise InputError(f"--vmc {text!r}: {expected}")
    if port is None:
        return host, DEFAULT_PORT
    if not port.isdigit() or not 1 <= int(port) <= 65535:
        raise InputError(f"--vmc {text!r}: port {port!r} is not a number from 1 to 65535; "
                         f"{expected}")
    return host, int(port)


def unity_pose(motion: Motion) -> tuple[list[str], np.ndarray, np.ndarray, np.ndarray]:
    """What the messages carry for each frame of ``motion`` (on the ``unity`` preset, see
    :func:`imuloco.core.rigs.apply_rig`), in Unity's axes.

    Returns
    -------
    names : the J bone names; root : (T, 3) the model root's position (the hips' ground
    point); positions : (T, J, 3) each bone's position local to its parent (``Hips``: to the
    root); rotations : (T, J, 4) local rotations x, y, z, w.
    """
    sk, t = motion.skeleton, len(motion.root)
    positions = np.repeat(sk.offsets[None], t, axis=0)
    positions[:, 0] = motion.root * [0.0, 1.0, 0.0]
    return (list(sk.names), to_unity_position(motion.root * [1.0, 0.0, 1.0]),
            to_unity_position(positions), to_unity_rotation(motion.rotations))


def _message(address: str, *args: str | float) -> bytes:
    """One OSC message's bytes, as python-osc encodes it."""
    builder = OscMessageBuilder(address=address)
    for a in args:
        builder.add_arg(a)
    return builder.build().dgram


class Encoder:
    """VMC bundles' bytes for a skeleton's bones (names (J,)), fast.

    Each message's address, type tags and name are encoded once by python-osc; a frame only
    appends its float32 values. python-osc alone (its builders parse every message they build,
    and the bundle parses them again) takes 4 ms a bundle here, an eighth of a frame at 30 fps
    on this 2-core machine; this takes 0.1 ms.
    """

    def __init__(self, names: Sequence[str]) -> None:
        zeros = (0.0,) * 7
        self.root = _message("/VMC/Ext/Root/Pos", "root", *zeros)[:-28]
        self.bones = [_message("/VMC/Ext/Bone/Pos", n, *zeros)[:-28] for n in names]
        self.ok = _message("/VMC/Ext/OK", 1)
        self.time = _message("/VMC/Ext/T", 0.0)[:-4]
        self.head = b"#bundle\x00" + osc_types.write_date(IMMEDIATELY)

    def bundles(self, root: np.ndarray, positions: np.ndarray, rotations: np.ndarray,
                times: np.ndarray) -> list[bytes]:
        """One bundle per frame (Unity's axes, see :func:`unity_pose`): root (T, 3),
        positions (T, J, 3), rotations (T, J, 4), times (T,) seconds (``/VMC/Ext/T``)."""
        t = len(root)
        root_q = np.broadcast_to([0.0, 0.0, 0.0, 1.0], (t, 1, 4))
        values = np.concatenate([np.concatenate([root[:, None], root_q], axis=2),
                                 np.concatenate([positions, rotations], axis=2)], axis=1)
        values = values.astype(">f4").tobytes()  # (T, 1 + J, 7) big-endian float32
        times = np.asarray(times, dtype=">f4").tobytes()
        heads = [self.root, *self.bones]
        out = []
        for k in range(t):
            frame = values[k * 28 * len(heads):(k + 1) * 28 * len(heads)]
            parts = [h + frame[i * 28:(i + 1) * 28] for i, h in enumerate(heads)]
            parts += [self.ok, self.time + times[4 * k:4 * k + 4]]
            out.append(self.head + b"".join(osc_types.write_int(len(m)) + m for m in parts))
        return out


class Bundles(Dispatcher):
    """A receiver's side, for checking a stream (tests, ``benchmarks/vmc_rate.py``): keeps each
    datagram's messages together as ``[(address, arguments), ...]`` in :attr:`packets` (python-osc's
    threaded server handles datagrams in threads of their own, so the messages of two bundles
    could interleave in per-address handlers)."""

    def __init__(self) -> None:
        super().__init__()
        self.lock = threading.Lock()
        self.packets: list[list[tuple[str, list]]] = []

    def call_handlers_for_packet(self, data: bytes, client_address: tuple[str, int]) -> list:
        messages = [(m.message.address, list(m.message.params)) for m in OscPacket(data).messages]
        with self.lock:
            self.packets.append(messages)
        return []


class VmcSender:
    """Sends a live session's frames to a VMC receiver at ``host:port``.

    Parameters
    ----------
    skeleton : the skeleton the frames are posed on (:attr:`LiveSession.skeleton`); it must be
        of the bundled sample's rig family, whose T-pose rest is known before any pose
        (:func:`imuloco.app.export.sample_rest`), as every shipped model's is.
    fps : the frames' rate (their ``index / fps`` is ``/VMC/Ext/T``).
    host, port : the receiver; a host name that does not resolve is an :class:`InputError`.
    """

    def __init__(self, skeleton: Skeleton, fps: float, host: str, port: int = DEFAULT_PORT
                 ) -> None:
        rest = sample_rest(skeleton)
        if rest is None:
            raise InputError(f"--vmc: the model's skeleton ({skeleton.num_joints} joints: "
                             f"{', '.join(skeleton.names[:6])}, ...) is not the bundled "
                             "sample's rig, whose T-pose the VMC bones are posed on; use a "
                             "model trained on it (every shipped model is)")
        self.skeleton, self.rest, self.fps = skeleton, rest, float(fps)
        # the preset's skeleton, once; a frame's local rotations are then re-expressed on its
        # rest as apply_rig does (the unity preset renames joints, inserts none)
        still = Motion(skeleton, np.tile([0.0, 0.0, 0.0, 1.0], (1, skeleton.num_joints, 1)),
                       np.zeros((1, 3)), self.fps)
        self.rig = apply_rig(still, RIG, rest).skeleton
        assert self.rig.num_joints == skeleton.num_joints
        self.encoder = Encoder(self.rig.names)
        self.host, self.port = host, port
        try:
            family, kind, proto, _, self.address = socket.getaddrinfo(
                host, port, type=socket.SOCK_DGRAM)[0]
        except (socket.gaierror, UnicodeError) as e:
            raise InputError(f"--vmc {host}:{port}: cannot resolve {host!r} ({e})") from None
        self.socket = socket.socket(family, kind, proto)
        self.socket.setblocking(False)  # UDP: a full buffer drops the bundle, never waits
        self.sent = 0  # bundles handed to the network
        self.dropped = 0  # bundles the network refused at once

    def motion(self, frames: Sequence[Frame]) -> Motion:
        """The frames (:class:`~imuloco.app.live.session.Frame`) as a motion on the ``unity``
        preset (world joint positions unchanged; :func:`imuloco.core.rigs.apply_rig`)."""
        rot = rebase_rotations(np.stack([f.rotations for f in frames]), self.skeleton.parents,
                               self.rest)
        return Motion(self.rig, rot, np.stack([f.root for f in frames]), self.fps)

    def send(self, frames: Sequence[Frame]) -> int:
        """Send one bundle per frame; returns how many went out."""
        if not frames:
            return 0
        _, root, positions, rotations = unity_pose(self.motion(frames))
        times = np.array([f.index for f in frames]) / self.fps
        sent = 0
        for bundle in self.encoder.bundles(root, positions, rotations, times):
            try:
                self.socket.sendto(bundle, self.address)
            except OSError as e:  # a full buffer, no route: UDP drops, the session goes on
                if not self.dropped:
                    log.warning("VMC: a bundle to %s:%d was dropped (%s); counting further "
                                "drops quietly", self.host, self.port, e.strerror or e)
                self.dropped += 1
            else:
                sent += 1
        self.sent += sent
        return sent

    def close(self) -> None:
        """Close the socket; one log line with the bundles sent (and dropped)."""
        self.socket.close()
        log.info("VMC: %d bundles sent to %s:%d%s", self.sent, self.host, self.port,
                 f", {self.dropped} dropped" if self.dropped else "")
