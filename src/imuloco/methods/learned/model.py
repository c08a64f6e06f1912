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
interface (a deep ensemble).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Sequence

import numpy as np
import torch
from torch import nn

CONTACT_PARTS = ("left_ankle", "right_ankle", "left_toe", "right_toe")


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
        k = len(self.members)
        hs = [None] * k if h is None else list(h.chunk(k, dim=0))
        out = [m.encode(x, hs[i]) for i, m in enumerate(self.members)]
        return torch.cat([y for y, _ in out], dim=-1), torch.cat([hn for _, hn in out], dim=0)

    def heads(self, y: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        k = len(self.members)
        pose, logit, logvar = (torch.stack(v) for v in zip(
            *(m.heads(part) for m, part in zip(self.members, y.chunk(k, dim=-1)))))
        prob = torch.sigmoid(logit).mean(0).clamp(1e-6, 1 - 1e-6)
        return (pose.mean(0), torch.log(prob) - torch.log1p(-prob),
                torch.logsumexp(logvar, dim=0) - math.log(k))

    def initial_state(self, batch: int = 1) -> torch.Tensor:
        return torch.cat([m.initial_state(batch) for m in self.members], dim=0)


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
        pos = [torch.zeros_like(rot[..., 0, :, 0])]
        for j in range(1, len(self.parents)):
            p = self.parents[j]
            grot.append(grot[p] @ rot[..., j, :, :])
            pos.append(pos[p] + (grot[p] @ self.offsets[j].unsqueeze(-1)).squeeze(-1))
        return torch.stack(pos, dim=-2)
