"""The network of the ``learned`` method and the differentiable pieces its losses need (torch).

``Reconstructor`` is a per-frame input layer, a stacked GRU and per-frame output heads. Causal
(the default), the same weights run a whole sequence at once (:meth:`Reconstructor.forward`) or
one frame at a time with a bounded hidden state; bidirectional (offline only), every frame's
pose reads the whole recording, both ways. Heads, per frame:

- ``pose`` : the standardized pose vector of :mod:`imuloco.methods.pose` (6-D local rotations,
  root height, root velocity in the heading frame, yaw rate);
- ``contact`` : logits of heel and toe contact of both feet (left heel, right heel, left toe,
  right toe);
- ``logvar`` : log of the expected squared joint position error (m^2) of the frame, trained by
  a Gaussian negative log-likelihood; its square root is the per-frame confidence in metres.

``Ensemble`` averages several ``Reconstructor`` s trained from other seeds behind the same
interface (a deep ensemble); :meth:`Ensemble.member_heads` also gives each member's pose.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Sequence

import numpy as np
import torch
from torch import nn

CONTACT_PARTS = ("left_ankle", "right_ankle", "left_toe", "right_toe")
# an Ensemble runs its stacked weights on at most this many frames, its members' GRUs on more
STACKED_FRAMES = 32


class _Network(nn.Module):
    """What the method needs of a network: :meth:`encode`, :meth:`heads` and a hidden state."""

    def forward(self, x: torch.Tensor, h: torch.Tensor | None = None
                ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """x : (B, T, C), h : (layers, B, hidden) or None -> pose, contact, logvar, new h."""
        y, h = self.encode(x, h)
        return (*self.heads(y), h)


class Reconstructor(_Network):
    """Sensor channels (B, T, C) -> pose (B, T, D), contact logits (B, T, 4), logvar (B, T, 1).

    Parameters
    ----------
    channels : C, the number of input channels (6 per sensor).
    pose_dim : D, the pose-vector length (6 J + 4).
    hidden : GRU width.
    layers : stacked GRU layers.
    dropout : dropout after the input layer and between GRU layers while training (it has no
        weights: models with any dropout share one file layout).
    bidirectional : a GRU that reads the sequence both ways (offline only: no ``h`` to carry).
    """

    def __init__(self, channels: int, pose_dim: int, hidden: int = 256, layers: int = 2,
                 dropout: float = 0.0, bidirectional: bool = False) -> None:
        super().__init__()
        self.inp = nn.Sequential(nn.Linear(channels, hidden), nn.GELU(), nn.Dropout(dropout))
        self.gru = nn.GRU(hidden, hidden, layers, batch_first=True,
                          dropout=dropout if layers > 1 else 0.0, bidirectional=bidirectional)
        width = hidden * (2 if bidirectional else 1)
        self.pose = nn.Linear(width, pose_dim)
        self.contact = nn.Linear(width, len(CONTACT_PARTS))
        self.logvar = nn.Linear(width, 1)
        self.hidden, self.layers, self.width = hidden, layers, width
        self.directions = 2 if bidirectional else 1

    def encode(self, x: torch.Tensor, h: torch.Tensor | None = None
               ) -> tuple[torch.Tensor, torch.Tensor]:
        """x : (B, T, C) -> the last GRU layer's outputs (B, T, width) (the features the
        heads read, and the novelty of :mod:`.method` measures), new h."""
        return self.gru(self.inp(x), h)

    def heads(self, y: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Features (B, T, width) -> pose (B, T, D), contact logits (B, T, 4), logvar."""
        return self.pose(y), self.contact(y), self.logvar(y)

    def initial_state(self, batch: int = 1) -> torch.Tensor:
        return torch.zeros(self.layers * self.directions, batch, self.hidden)


class Ensemble(_Network):
    """K Reconstructors trained from other seeds, read as one: a deep ensemble
    (Lakshminarayanan et al. 2017, NeurIPS), whose average is less at the mercy of one
    training run than any member.

    Every member reads and writes the ensemble's standardization (:meth:`restandardized`).
    Features are the members' side by side (B, T, K width), the hidden state their states
    stacked (K layers, B, hidden). Outputs: the mean standardized pose, the contact logit of
    the mean probability and the log of the mean expected squared error.
    """

    def __init__(self, members: Sequence[Reconstructor]) -> None:
        super().__init__()
        self.members = nn.ModuleList(members)
        first = members[0]
        self.hidden, self.layers, self.directions = first.hidden, first.layers, first.directions
        self.width = len(members) * first.width
        self._stacked: StackedWeights | None = None  # see _weights
        self.register_load_state_dict_post_hook(self._forget_weights)

    @classmethod
    def of_size(cls, k: int, channels: int, pose_dim: int, **kw) -> Ensemble:
        """K fresh members, for loading a saved ensemble's state."""
        return cls([Reconstructor(channels, pose_dim, **kw) for _ in range(k)])

    @staticmethod
    def restandardized(net: Reconstructor, x_scale: np.ndarray, x_shift: np.ndarray,
                       y_scale: np.ndarray, y_shift: np.ndarray) -> Reconstructor:
        """A copy of ``net`` that reads ``x`` where it read ``x * x_scale + x_shift`` (C,) and
        writes ``p * y_scale + y_shift`` (D,) where it wrote ``p``: the maps folded into its
        first and pose layers, so that members standardized their own way cost nothing."""
        net = copy.deepcopy(net)
        f = torch.float64
        with torch.no_grad():
            inp, pose = net.inp[0], net.pose
            w, b = inp.weight.to(f), inp.bias.to(f)
            inp.weight.copy_(w * torch.as_tensor(x_scale, dtype=f))
            inp.bias.copy_(b + w @ torch.as_tensor(x_shift, dtype=f))
            ys = torch.as_tensor(y_scale, dtype=f)
            pose.weight.copy_(pose.weight.to(f) * ys[:, None])
            pose.bias.copy_(pose.bias.to(f) * ys + torch.as_tensor(y_shift, dtype=f))
        return net

    def encode(self, x: torch.Tensor, h: torch.Tensor | None = None
               ) -> tuple[torch.Tensor, torch.Tensor]:
        """x : (B, T, C) -> the members' features side by side (B, T, K width), new h. A few
        frames (a stream's step) run on the stacked weights (:class:`StackedWeights`, one
        Python step a frame for all members); a whole recording runs each member's own GRU
        over it, one call each (torch's compiled recurrence: 3.7 against 5.5 CPU s for 6,000
        frames of the shipped 4-member shin model, one thread)."""
        if not (self._by_member() or self.directions == 2 or x.shape[1] > STACKED_FRAMES):
            return self._weights().encode(x, h)
        k = len(self.members)
        hs = [None] * k if h is None else list(h.chunk(k, dim=0))
        out = [m.encode(x, hs[i]) for i, m in enumerate(self.members)]
        return torch.cat([y for y, _ in out], dim=-1), torch.cat([hn for _, hn in out], dim=0)

    def heads(self, y: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        poses, logit, logvar = self.member_heads(y)
        return poses.mean(-2), logit, logvar

    def member_heads(self, y: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """:meth:`heads` with every member's pose (B, T, K, D) in place of their mean."""
        k = len(self.members)
        if self._by_member():
            pose, logit, logvar = (torch.stack(v, dim=-2) for v in zip(
                *(m.heads(part) for m, part in zip(self.members, y.chunk(k, dim=-1)))))
            logvar = logvar[..., 0]
        else:
            out = self._weights().heads(y)
            pose, logit, logvar = out.split([out.shape[-1] - 5 * k, 4 * k, k], dim=-1)
            pose, logit = pose.unflatten(-1, (k, -1)), logit.unflatten(-1, (k, 4))
        prob = torch.sigmoid(logit).mean(-2).clamp(1e-6, 1 - 1e-6)
        return (pose, torch.log(prob) - torch.log1p(-prob),
                torch.logsumexp(logvar, dim=-1, keepdim=True) - math.log(k))

    def _by_member(self) -> bool:
        """Whether to run the members' own modules rather than their stacked weights: while
        training, and while tracing (an ONNX export: the stacked weights would be built
        inside the graph, and the recurrence's loop over frames fixed to the example's
        length). Causal members in inference run stacked (:class:`StackedWeights`)."""
        return self.training or torch.jit.is_tracing()

    def _weights(self) -> StackedWeights:
        """The members' weights stacked (:class:`StackedWeights`), taken at first use and
        dropped whenever the weights may change: a mode change (``train``, ``eval``), loading
        a state dict, moving or casting (``to``, ``float``). A member's weights written in place
        by hand need another ``eval()`` to be seen."""
        if self._stacked is None:
            self._stacked = StackedWeights(self.members)
        return self._stacked

    def _forget_weights(self, *_args) -> None:
        self._stacked = None

    def train(self, mode: bool = True) -> Ensemble:
        self._forget_weights()
        return super().train(mode)

    def _apply(self, fn, *args, **kwargs):
        self._forget_weights()
        return super()._apply(fn, *args, **kwargs)

    def initial_state(self, batch: int = 1) -> torch.Tensor:
        return torch.cat([m.initial_state(batch) for m in self.members], dim=0)


class StackedWeights:
    """An :class:`Ensemble`'s K causal members as one computation: their weights stacked along
    a leading member axis, so that each step is one batched matrix product per layer
    (:func:`torch.baddbmm`) for all members instead of K module calls (a 4-member stream step
    spent most of its time in the members' per-call overhead).

    PyTorch's own recipe for ensembles (``torch.func.stack_module_state`` with ``vmap``) does
    not apply: torch 2.13 has no batching rule for ``aten::gru``. So the GRU recurrence is
    written out here, the equations of :class:`torch.nn.GRU`'s documentation (tested equal to
    the members' modules to float precision):
    ``r = sigmoid(W_ir x + b_ir + W_hr h + b_hr)``, ``z`` likewise, ``n = tanh(W_in x + b_in
    + r (W_hn h + b_hn))``, ``h' = n + z (h - n)``. The heads of all members are one linear
    layer on the features side by side, its weights block-diagonal (each member's pose,
    contact and logvar rows read that member's features only)."""

    def __init__(self, members: Sequence[Reconstructor]) -> None:
        k, first = len(members), members[0]
        self.k, self.hidden, self.layers = k, first.hidden, first.layers

        def stacked(name: str) -> torch.Tensor:  # (K, in, out): a batched right factor
            return torch.stack([getattr(m.gru, name).detach().T for m in members]).contiguous()

        def bias(name: str) -> torch.Tensor:  # (K, 1, out)
            return torch.stack([getattr(m.gru, name).detach() for m in members])[:, None]

        with torch.no_grad():
            self.inp_w = torch.cat([m.inp[0].weight for m in members]).detach()  # (K H, C)
            self.inp_b = torch.cat([m.inp[0].bias for m in members]).detach()
            self.w_ih = [stacked(f"weight_ih_l{i}") for i in range(self.layers)]
            self.w_hh = [stacked(f"weight_hh_l{i}") for i in range(self.layers)]
            self.b_ih = [bias(f"bias_ih_l{i}") for i in range(self.layers)]
            self.b_hh = [bias(f"bias_hh_l{i}") for i in range(self.layers)]
            self.head_w = torch.cat([torch.block_diag(*(getattr(m, head).weight for m in members))
                                     for head in ("pose", "contact", "logvar")])
            self.head_b = torch.cat([getattr(m, head).bias for head in ("pose", "contact", "logvar")
                                     for m in members])

    def encode(self, x: torch.Tensor, h: torch.Tensor | None = None
               ) -> tuple[torch.Tensor, torch.Tensor]:
        """x : (B, T, C), h : (K layers, B, hidden) or None -> features (B, T, K hidden), the
        members' side by side as :meth:`Ensemble.encode`'s, and the new h."""
        b, t, _ = x.shape
        k, n = self.k, self.hidden
        a = nn.functional.gelu(nn.functional.linear(x, self.inp_w, self.inp_b))
        a = a.view(b, t, k, n).permute(2, 1, 0, 3).reshape(k, t * b, n)  # frame-major rows
        h = x.new_zeros(k, self.layers, b, n) if h is None else h.view(k, self.layers, b, n)
        last = []
        for i in range(self.layers):
            gi = torch.baddbmm(self.b_ih[i], a, self.w_ih[i]).view(k, t, b, 3 * n)
            gi_rz, gi_n = (g.unbind(1) for g in gi.split([2 * n, n], dim=-1))
            hi, out = h[:, i], []
            for s in range(t):  # the recurrence: frame by frame
                gh_rz, gh_n = torch.baddbmm(self.b_hh[i], hi, self.w_hh[i]).split([2 * n, n], -1)
                r, z = torch.sigmoid(gi_rz[s] + gh_rz).chunk(2, dim=-1)
                new = torch.tanh(torch.addcmul(gi_n[s], r, gh_n))
                hi = torch.addcmul(new, z, hi - new)
                out.append(hi)
            a = torch.stack(out, dim=1).view(k, t * b, n)
            last.append(hi)
        feats = a.view(k, t, b, n).permute(2, 1, 0, 3).reshape(b, t, k * n)
        return feats, torch.stack(last, dim=1).view(k * self.layers, b, n)

    def heads(self, y: torch.Tensor) -> torch.Tensor:
        """Features (B, T, K width) -> the members' standardized poses (D each), contact logits
        (4 each) and logvars (1 each), side by side: (B, T, K (D + 5))."""
        return nn.functional.linear(y, self.head_w, self.head_b)


def rotation_from_6d(d: torch.Tensor) -> torch.Tensor:
    """6-D rotations (..., 6) -> matrices (..., 3, 3), the Gram-Schmidt map of
    :func:`imuloco.ops.rotations.from_6d` (first two columns, then their cross product)."""
    a = nn.functional.normalize(d[..., :3], dim=-1)
    b = d[..., 3:] - (a * d[..., 3:]).sum(-1, keepdim=True) * a
    b = nn.functional.normalize(b, dim=-1)
    return torch.stack([a, b, torch.linalg.cross(a, b)], dim=-1)


class TorchFK(nn.Module):
    """Joint positions relative to the root from local rotation matrices, differentiable.

    :func:`imuloco.ops.kinematics.fk` is numpy; the losses need gradients, so the same
    recursion is written again over torch tensors.

    Parameters
    ----------
    offsets : ndarray, shape (J, 3), metres.
    parents : ndarray, shape (J,), parents[j] < j.
    """

    def __init__(self, offsets: np.ndarray, parents: np.ndarray) -> None:
        super().__init__()
        self.register_buffer("offsets", torch.as_tensor(np.asarray(offsets), dtype=torch.float32))
        self.parents = [int(p) for p in parents]

    def forward(self, rot: torch.Tensor) -> torch.Tensor:
        """rot : (..., J, 3, 3) local rotations -> positions (..., J, 3), root at the origin."""
        grot = [rot[..., 0, :, :]]
        # the root at the origin; not zeros_like, whose shape an ONNX trace fixes to the example's
        pos = [rot[..., 0, :, 0] * 0.0]
        for j in range(1, len(self.parents)):
            p = self.parents[j]
            grot.append(grot[p] @ rot[..., j, :, :])
            pos.append(pos[p] + (grot[p] @ self.offsets[j].unsqueeze(-1)).squeeze(-1))
        return torch.stack(pos, dim=-2)

