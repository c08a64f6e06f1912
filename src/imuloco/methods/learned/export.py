"""ONNX export of a ``learned`` model, to run it on a phone or in a browser.

The exported graph is the whole per-frame network with its input standardization and output
de-standardization (and, for a mirrored model, the mirroring) baked in:

- inputs ``signals`` (1, T, 6 S) raw channels at the model rate (m/s^2, rad/s; sensor order
  and fps in the metadata) and ``h`` (the metadata's ``h_shape``: layers, 1, hidden; members
  x layers for an ensemble), zeros at the start;
- outputs ``pose`` (1, T, 6 J + 4) pose vectors (:mod:`imuloco.methods.pose`), ``contacts``
  (1, T, 4) probabilities, ``sigma`` (1, T) metres, ``h_out`` to feed back, and
  ``novelty_frame`` (1, T): each frame's novelty before its causal smoothing (NaN for a model
  file from before novelty was measured), and ``spread`` (1, T) metres: an ensemble's members'
  disagreement (:func:`imuloco.methods.learned.method.member_spread`; NaN for one network).

The host smooths the novelty as :meth:`imuloco.methods.learned.method.Learned._novelty` does,
``n[0] = f[0]``, ``n[k] = a f[k] + (1 - a) n[k - 1]`` with ``a`` the metadata's
``novelty_alpha`` (carried across calls like ``h``); a frame is unreliable where ``n`` exceeds
``novelty_threshold``. A model with a ``calibration`` (metadata, JSON) predicts the error
``exp(coef[0]) * prod_k score_k ** coef[k]`` over its ``scores`` (``novelty``: n; ``sigma_m``:
sigma; ``spread_m``: spread), as :func:`imuloco.methods.base.calibrated_error`.

Output frame k is the pose of input frame k - ``lag`` (metadata: the model's look-ahead in
frames; 0 for a model without). T may be 1 (online, one frame per call carrying ``h``) or a
whole recording. Decoding pose vectors into joint rotations and the root path is left to the
host (a few lines: Gram-Schmidt per joint and an integration of the velocity), as is foot
pinning, and the average of the root's height (the pose vector's column 6 J) over the
metadata's ``height_weights`` (a centred window,
:attr:`imuloco.methods.learned.method.Learned.height_weights`: frame k's height is the
weighted heights of frames k - r to k + r, frames before the first being the first; ``[1.0]``
for none).
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import torch
from torch import nn

from imuloco.core.mirror import mirror_pairs
from imuloco.io.atomic import atomic_path, check_output
from imuloco.methods.learned.method import CONTACT_SWAP, Learned
from imuloco.methods.learned.model import CONTACT_PARTS, Ensemble, TorchFK, rotation_from_6d


class _Exported(nn.Module):
    def __init__(self, model: Learned) -> None:
        super().__init__()
        f = torch.float32
        self.net = model.net_
        self.register_buffer("imap", torch.as_tensor(model.input_map_, dtype=f))
        self.register_buffer("x_mean", torch.as_tensor(model.x_mean_, dtype=f))
        self.register_buffer("x_std", torch.as_tensor(model.x_std_, dtype=f))
        self.register_buffer("y_mean", torch.as_tensor(model.y_mean_, dtype=f))
        self.register_buffer("y_std", torch.as_tensor(model.y_std_, dtype=f))
        self.mirror = bool(model.output_mirror_)
        self.novelty = model.novelty_mean_ is not None
        if self.novelty:  # Learned._novelty's distance, its smoothing left to the host
            self.register_buffer("n_mean", torch.as_tensor(model.novelty_mean_, dtype=f))
            self.register_buffer("n_precision", torch.as_tensor(
                model.novelty_precision_ / (len(model.novelty_mean_) * model.novelty_scale_),
                dtype=f))
        sk = model.skeleton_
        self.spread = (_MemberSpread(model.y_mean_, model.y_std_, sk.offsets, sk.parents)
                       if isinstance(model.net_, Ensemble) else None)
        self.j = sk.num_joints
        if self.mirror:
            parents = np.asarray(sk.parents)
            frames = np.asarray(model.frames_)
            left = frames[np.where(parents >= 0, parents, 0)].swapaxes(-1, -2)
            left[parents < 0] = np.diag([-1.0, 1.0, 1.0])
            self.register_buffer("left", torch.as_tensor(left, dtype=f))
            self.register_buffer("right", torch.as_tensor(frames, dtype=f))
            self.swap = [int(k) for k in mirror_pairs(sk)]

    def forward(self, signals: torch.Tensor, h: torch.Tensor) -> tuple[torch.Tensor, ...]:
        x = (signals @ self.imap.T - self.x_mean) / self.x_std
        feats, h_out = self.net.encode(x, h)
        if self.spread is None:
            p, logit, logvar = self.net.heads(feats)
        else:
            poses, logit, logvar = self.net.member_heads(feats)
            p = poses.mean(-2)
        sigma = torch.exp(0.5 * logvar[..., 0])
        spread = torch.full_like(sigma, float("nan")) if self.spread is None else self.spread(poses)
        if self.novelty:
            prec = self.n_precision if self.n_precision.dim() == 3 else self.n_precision[None]
            d = (feats - self.n_mean).reshape(*feats.shape[:2], prec.shape[0], 1, prec.shape[1])
            novelty = ((d @ prec) * d).sum((-1, -2, -3))  # one block per ensemble member
        else:
            novelty = torch.full_like(sigma, float("nan"))
        pose = p * self.y_std + self.y_mean
        contacts = torch.sigmoid(logit)
        if self.mirror:  # see Learned._mirror_vectors
            j = self.j
            rot = rotation_from_6d(pose[..., : 6 * j].reshape(pose.shape[0], pose.shape[1], j, 6))
            rot = self.left @ rot[:, :, self.swap] @ self.right
            six = torch.cat([rot[..., :, 0], rot[..., :, 1]], dim=-1).reshape(
                pose.shape[0], pose.shape[1], 6 * j)
            sign = torch.ones(4)
            sign[1] = -1.0
            sign[3] = -1.0
            pose = torch.cat([six, pose[..., 6 * j:] * sign], dim=-1)
            contacts = contacts[..., CONTACT_SWAP]
        return pose, contacts, sigma, h_out, novelty, spread


class _MemberSpread(nn.Module):
    """:func:`imuloco.methods.learned.method.member_spread` in the graph, from the members'
    standardized poses (..., K, D) (the numpy function runs offline and in the stream: 0.23 ms
    of a stream step, where torch's per-operation overhead made it 0.63)."""

    def __init__(self, y_mean: np.ndarray, y_std: np.ndarray, offsets: np.ndarray,
                 parents: np.ndarray) -> None:
        super().__init__()
        self.register_buffer("y_mean", torch.as_tensor(np.asarray(y_mean), dtype=torch.float32))
        self.register_buffer("y_std", torch.as_tensor(np.asarray(y_std), dtype=torch.float32))
        self.fk = TorchFK(offsets, parents)
        self.j = len(self.fk.parents)

    def forward(self, poses: torch.Tensor) -> torch.Tensor:
        v = poses * self.y_std + self.y_mean
        pos = self.fk(rotation_from_6d(v[..., : 6 * self.j].unflatten(-1, (self.j, 6))))[..., 1:, :]
        dev = ((pos - pos.mean(-3, keepdim=True)) ** 2).sum((-1, -3))
        return (dev.mean(-1) / (poses.shape[-2] - 1)).sqrt()


def export_onnx(model: Learned, path: str | Path, overwrite: bool = False) -> Path:
    """Write ``model`` as an ONNX graph (see the module docstring); the metadata hold the
    placements, fps, joint names and parents, and the contact order. Checked with
    :func:`onnx.checker.check_model`. Written atomically (:func:`imuloco.io.atomic.atomic_path`):
    a failed export leaves ``path`` as it was."""
    import onnx  # the [deep] extra's; only exporting needs it

    path = Path(path)
    check_output(path, overwrite)
    module = _Exported(model).eval()
    c = model.x_mean_.shape[0]
    x = torch.zeros(1, 5, c)
    h = model.net_.initial_state(1)
    with atomic_path(path) as tmp:  # a temporary file beside path, renamed when complete
        with warnings.catch_warnings():
            # the TorchScript-based exporter (no onnxscript needed) announces its deprecation
            warnings.simplefilter("ignore")
            torch.onnx.export(module, (x, h), str(tmp), dynamo=False, opset_version=17,
                              input_names=["signals", "h"],
                              output_names=["pose", "contacts", "sigma", "h_out",
                                            "novelty_frame", "spread"],
                              dynamic_axes={"signals": {1: "frames"}, "pose": {1: "frames"},
                                            "contacts": {1: "frames"}, "sigma": {1: "frames"},
                                            "novelty_frame": {1: "frames"},
                                            "spread": {1: "frames"}})
        proto = onnx.load(str(tmp))
        sk = model.skeleton_
        meta = {"method": model.name, "placements": json.dumps(model.placements_),
                "fps": str(model.fps_), "joints": json.dumps(list(sk.names)),
                "parents": json.dumps([int(p) for p in sk.parents]),
                "offsets_m": json.dumps(np.asarray(sk.offsets).round(6).tolist()),
                "contacts": json.dumps(list(CONTACT_PARTS)), "lag": str(model.lookahead),
                "h_shape": json.dumps(list(h.shape)),
                "height_weights": json.dumps(model.height_weights.round(9).tolist()),
                "channels": "per sensor acc x,y,z (m/s^2) then gyro x,y,z (rad/s), sensor "
                            "frame"}
        if model.novelty_mean_ is not None:
            meta.update(novelty_alpha=repr(model.novelty_alpha_),
                        novelty_threshold=repr(model.novelty_threshold_))
        if model.calibration_ is not None:
            meta["calibration"] = json.dumps(model.calibration_)
        for k, v in meta.items():
            entry = proto.metadata_props.add()
            entry.key, entry.value = k, v
        onnx.checker.check_model(proto)
        onnx.save(proto, str(tmp))
    return path
