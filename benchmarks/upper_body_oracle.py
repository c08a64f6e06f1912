"""How well can the upper body of unseen motion be known from the legs? An oracle's measurement.

    python benchmarks/upper_body_oracle.py --data ../shared/data \
        [--split heldout-styles|cross-dataset] [--seeds 0,1,2] [--epochs 12]

One shin sensor sees the legs, and only through them the arms and trunk. Here a bidirectional
GRU (the shape of ``learned[bidirectional=True]``) is given far more than a sensor: the *true*
lower body of every frame, whole clip both ways (the leg joints' positions relative to the
pelvis in the heading frame, the pelvis height, its velocity in the heading frame and its turn
rate). It is trained on the split's training clips to give the upper body's joint positions
(same frame; mean squared error, standardized), and tested on its test clips. Its upper-body
error is what knowing the legs exactly leaves; a method that reads the legs from a sensor does
no better there, short of seeing the arms. Printed per seed: the upper body's MPJPE over the
skeleton's upper joints (:func:`imuloco.measures.metrics.body_halves`) and over the canonical
upper parts (``cross-dataset``'s measure), the training set's mean upper pose beside it, and
the whole body's MPJPE if the lower body were exact, which bounds what a method whose upper
body is no better than the oracle's can reach.

Splits: ``heldout-styles`` (``bandai-namco-2``: styles ``exhausted`` and ``feminine`` left
out, as ``bench``) and ``cross-dataset`` (both Bandai-Namco sets -> ``cmu-iclone``'s ground
truth retargeted onto the training skeleton, :func:`imuloco.lab.bench.
truth_on_training_rig`; the measure whose floor is zero). Needs torch (the ``[deep]`` extra).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import torch

from imuloco.core.bodymap import UPPER_PARTS
from imuloco.core.motion import Motion, MotionDatabase
from imuloco.lab.bench import load_cross_dataset, load_data
from imuloco.lab.protocols import folds
from imuloco.measures.metrics import body_halves, heading_of, local_positions
from imuloco.ops.heading import to_heading_frame

WINDOW, STRIDE, BATCH, HIDDEN, PEAK_LR = 120, 30, 32, 128, 4e-3


def split(data: Path, name: str) -> tuple[MotionDatabase, MotionDatabase]:
    """The split's training clips and its test clips (the latter on the training skeleton)."""
    if name == "heldout-styles":
        ((_, train, test),) = folds(load_data([data / "bandai-namco-2"], progress=False), name)
        return train, test
    train, cmu, truth = load_cross_dataset([data / "bandai-namco-2", data / "bandai-namco-1"],
                                           [data / "cmu-iclone"])
    return train, MotionDatabase([truth[lab["name"]] for lab in cmu.labels], cmu.labels)


def pairs(m: Motion, upper: np.ndarray, lower: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The oracle's inputs (T, F) from the true lower body and its targets (T, 3 U)."""
    local = local_positions(m)
    pos = m.positions()
    heading = heading_of(m, pos)
    velocity = np.diff(pos[:, 0], axis=0, prepend=pos[:1, 0]) * m.fps
    velocity = to_heading_frame(velocity[:, None], np.zeros_like(velocity), heading)[:, 0]
    turn = np.diff(np.unwrap(heading), prepend=heading[0]) * m.fps
    x = np.concatenate([local[:, lower].reshape(len(local), -1), pos[:, :1, 1], velocity,
                        turn[:, None]], axis=1)
    return x.astype(np.float32), local[:, upper].reshape(len(local), -1).astype(np.float32)


class Oracle(torch.nn.Module):
    def __init__(self, inputs: int, outputs: int) -> None:
        super().__init__()
        self.gru = torch.nn.GRU(inputs, HIDDEN, 2, batch_first=True, bidirectional=True)
        self.out = torch.nn.Linear(2 * HIDDEN, outputs)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.out(self.gru(x)[0])


def window(a: np.ndarray, start: int) -> np.ndarray:
    a = a[start:start + WINDOW]
    return np.pad(a, ((0, WINDOW - len(a)), (0, 0)), mode="edge")


def train_oracle(train: list[tuple[np.ndarray, np.ndarray]], epochs: int, seed: int):
    """The oracle fitted on (inputs, targets) clips; returns it and the standardizations.
    A loop of its own: ``learned``'s trainer (:mod:`imuloco.methods.learned.train`) learns
    from simulated sensor signals and decodes rotations, not from poses to positions."""
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    x_all, y_all = (np.concatenate(a) for a in zip(*train))
    norm = (x_all.mean(0), x_all.std(0) + 1e-6, y_all.mean(0), y_all.std(0) + 1e-6)
    net = Oracle(x_all.shape[1], y_all.shape[1])
    starts = [(i, s) for i, (x, _) in enumerate(train)
              for s in range(0, max(1, len(x) - WINDOW + 1), STRIDE)]
    steps = -(-len(starts) // BATCH)
    opt = torch.optim.AdamW(net.parameters(), PEAK_LR / 2, weight_decay=1e-4)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, PEAK_LR, total_steps=epochs * steps)
    t0 = time.perf_counter()
    for epoch in range(epochs):
        order = rng.permutation(len(starts))
        for b in range(steps):
            chosen = [starts[k] for k in order[b * BATCH:(b + 1) * BATCH]]
            x = np.stack([(window(train[i][0], s) - norm[0]) / norm[1] for i, s in chosen])
            y = np.stack([(window(train[i][1], s) - norm[2]) / norm[3] for i, s in chosen])
            loss = torch.nn.functional.mse_loss(net(torch.from_numpy(x)), torch.from_numpy(y))
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
        print(f"  epoch {epoch + 1}/{epochs}, {time.perf_counter() - t0:.0f} s", flush=True)
    return net.eval(), norm


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, required=True, help="the shared data folder")
    ap.add_argument("--split", choices=("heldout-styles", "cross-dataset"),
                    default="heldout-styles")
    ap.add_argument("--seeds", default="0", help="training seeds, e.g. 0,1,2")
    ap.add_argument("--epochs", type=int, default=12)
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    train_db, test_db = split(args.data, args.split)
    sk = train_db.clips[0].skeleton
    upper, lower = body_halves(sk)
    parts = [list(upper).index(sk.part(p)) for p in UPPER_PARTS]
    train = [pairs(m, upper, lower) for m in train_db.clips]
    test = [pairs(m, upper, lower) for m in test_db.clips]
    truth = np.concatenate([y for _, y in test]).reshape(-1, len(upper), 3)
    mean_pose = np.linalg.norm(truth - np.concatenate([y for _, y in train]).mean(0).reshape(
        len(upper), 3), axis=-1)
    print(f"{args.split}: {len(train)} training clips, {len(test)} test clips "
          f"({len(truth)} frames); {len(upper)} upper joints, {len(lower)} lower")
    for seed in (int(s) for s in args.seeds.split(",")):
        net, (xm, xs, ym, ys) = train_oracle(train, args.epochs, seed)
        with torch.no_grad():
            pred = np.concatenate([net(torch.from_numpy((x - xm) / xs)[None])[0].numpy() * ys + ym
                                   for x, _ in test]).reshape(truth.shape)
        err = np.linalg.norm(pred - truth, axis=-1)
        whole = 100 * err.mean() * len(upper) / (len(upper) + len(lower))
        print(f"seed {seed}: upper joints {100 * err.mean():.2f} cm (mean pose "
              f"{100 * mean_pose.mean():.2f}), upper parts {100 * err[:, parts].mean():.2f} cm "
              f"(mean pose {100 * mean_pose[:, parts].mean():.2f}); whole body with the lower "
              f"body exact {whole:.2f} cm", flush=True)


if __name__ == "__main__":
    main()
