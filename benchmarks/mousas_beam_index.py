"""Would an index over segments' first frames make mousas2017's beam fast? A measurement.

    python benchmarks/mousas_beam_index.py [--data ../shared/data/bandai-namco-2] \
        [--db-frames 100000] [--width 2048] [--steps 300] [-o TABLE.md]

Fits ``mousas2017`` on a database of ``--db-frames`` frames built as ``imuloco bench --speed``
builds it (right ankle, ``phone`` noise, the same held-out test clip) and streams the test
clip (looped to ``--steps`` steps, one BLAS thread). Each step of the beam
(:class:`imuloco.methods.mousas2017.beam.SegmentBeam`) tests every segment's first frame for
entry: its entry mass times its emission against the ``width``-th largest kept mass. Within a
block all first frames share one group's precision ``P`` (eq. 9), so that test is a ball
around the sample in the whitened space ``y L`` (``P = L L'``), and an index (a k-d tree)
could return the entrants without scanning them all. This measures what such an index would
have to beat, per step, in one process (CPU time of this thread):

- how flat the emissions are (share of the frame states within e^-60 and e^-10 of the best)
  and how many segments pass the entry test (the numpy beam step's entrants);
- that the ball query returns the entry test's segments (the whitening is right);
- the whole compiled step (beam and exact) against the index's calls alone: the nearest first
  frame of each block (which the step needs as its emissions' reference) and the ball of each
  block, for scipy's ``cKDTree`` and scikit-learn's ``KDTree``.

A measurement to decide a design, never a fit: nothing here changes the method.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree
from sklearn.neighbors import KDTree
from threadpoolctl import threadpool_limits

from imuloco.io.atomic import atomic_write, check_output
from imuloco.lab import speed
from imuloco.lab.bench import load_data
from imuloco.methods import method_class
from imuloco.methods.mousas2017.beam import SegmentBeam
from imuloco.methods.training import TEST_SEED_OFFSET, synthesize


def fitted_model(data: Path, frames: int):
    """mousas2017 fitted on ``frames`` database frames and the test clip's signals (T, 6)."""
    db, test_db = speed._split_test(load_data(data))
    test = synthesize(test_db, ["right_ankle"], "phone", TEST_SEED_OFFSET)[0]
    big, _ = speed.build_database(db, frames, 0)
    examples = synthesize(big, ["right_ankle"], "phone", 0)
    return speed._fit(method_class("mousas2017"), {}, examples, ["right_ankle"], "phone"), \
        test.signals


class FirstFrameIndex:
    """Per block, the whitened first-frame means ``mu_y L`` of its segments (H, dy) and the
    Cholesky factor L of the block's first group's precision."""

    def __init__(self, beam: SegmentBeam) -> None:
        fs, counts = beam.fs, beam.counts
        self.factors, self.points = [], []
        for b in range(counts.size):
            segs = np.arange(beam.seg0[b], beam.seg0[b] + counts[b])
            chol = np.linalg.cholesky(fs.prec[beam.first_group[segs[0]]])
            self.factors.append(chol)
            self.points.append(fs.mu_y[beam.states[segs, 0]].astype(np.float64) @ chol)
        self.scipy = [cKDTree(p) for p in self.points]
        self.sklearn = [KDTree(p) for p in self.points]

    def queries(self, y: np.ndarray) -> list[np.ndarray]:
        return [y @ chol for chol in self.factors]


def measure(model, signals: np.ndarray, width: int, steps: int) -> dict[str, float]:
    """The figures of the module docstring, as medians (counts) or means (times, µs) a step."""
    rows = np.concatenate([signals] * int(np.ceil(steps / len(signals))))[:steps]
    fs = model.states_
    clock = time.thread_time
    out: dict[str, list[float]] = {k: [] for k in (
        "within60", "within10", "entrants", "first_mass", "ball_found", "ball_extra",
        "beam_step", "exact_step", "ckd_nearest", "ckd_ball", "ckd_call", "skl_nearest",
        "skl_ball")}
    for y in rows:
        ll = fs.log_emission(y).astype(np.float64)
        out["within60"].append(float(np.mean(ll >= ll.max() - 60.0)))
        out["within10"].append(float(np.mean(ll >= ll.max() - 10.0)))
    # the numpy beam step, its entrants recorded
    stream = model.stream(beam=width, engine="numpy")
    beam = stream._beam
    index = FirstFrameIndex(beam)
    seen: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    entrants = beam._entrants

    def recording(seg, mass, entry, raw, offset):
        new, new_b = entrants(seg, mass, entry, raw, offset)
        seen.append((new, raw, seg))
        return new, new_b

    beam._entrants = recording
    radii = []
    for y in rows:
        seen.clear()
        stream.step(y)
        new, raw, before = seen[0]
        out["entrants"].append(new.size)
        out["first_mass"].append(float(beam.alpha[:, 0].sum() / beam.alpha.sum()))
        if raw is None or stream.t == 1:
            radii.append(None)
            continue
        # the ball of each block that holds its entrants: radius = the farthest entrant's
        qs = index.queries(y)
        r, found, extra = [], 0, 0
        for b, (tree, q) in enumerate(zip(index.scipy, qs)):
            mine = new[beam.block[new] == b] - beam.seg0[b]
            if mine.size == 0:
                r.append(0.0)
                continue
            d = np.sqrt(((index.points[b][mine] - q) ** 2).sum(1))
            r.append(float(d.max()))
            # the ball holds every entrant by its radius; are its other segments all in the
            # beam before the step (not entrants)? Then ball and entry test are one set
            ball = np.asarray(tree.query_ball_point(q, d.max() * (1 + 1e-9)), dtype=int)
            kept = before[beam.block[before] == b] - beam.seg0[b]
            found += ball.size
            extra += np.setdiff1d(ball, np.concatenate([mine, kept])).size
        out["ball_found"].append(found)
        out["ball_extra"].append(extra)
        radii.append(r)
    # times: the compiled steps, then the index's calls on the same samples
    for key, kw in (("beam_step", {"beam": width}), ("exact_step", {"beam": 0})):
        st = model.stream(engine="numba", **kw)
        for y in rows[:10]:
            st.step(y)
        for y in rows:
            c0 = clock()
            st.step(y)
            out[key].append(clock() - c0)
    # one call per block and query: (tree, query point, radius) -> the call
    calls = {
        "ckd_nearest": lambda t, q, rb: t.query(q, k=1),
        "ckd_ball": lambda t, q, rb: t.query_ball_point(q, rb),
        "ckd_call": lambda t, q, rb: t.query_ball_point(q, 0.0),
        "skl_nearest": lambda t, q, rb: t.query(q[None], k=1),
        "skl_ball": lambda t, q, rb: t.query_radius(q[None], rb),
    }
    for y, r in zip(rows, radii):
        if r is None:
            continue
        qs = index.queries(y)
        for key, call in calls.items():
            trees = index.scipy if key.startswith("ckd") else index.sklearn
            c0 = clock()
            for tree, q, rb in zip(trees, qs, r):
                call(tree, q, rb)
            out[key].append(clock() - c0)
    res = {k: float(np.median(v)) for k, v in out.items() if k in (
        "within60", "within10", "entrants", "first_mass")}
    res["entrants_p10"], res["entrants_p90"] = (float(x) for x in np.percentile(
        out["entrants"], [10, 90]))
    res["ball_found"], res["ball_extra"] = sum(out["ball_found"]), sum(out["ball_extra"])
    res.update({k: float(np.mean(v)) * 1e6 for k, v in out.items() if k.endswith(
        ("_step", "_nearest", "_ball", "_call"))})
    res["states"], res["segments"] = fs.lin.shape[1], beam.num_segments
    res["blocks"] = beam.counts.size
    return res


def table(res: dict[str, float], frames: int, width: int) -> str:
    rows = [
        ("frame states within e^-60 / e^-10 of the best emission (median)",
         f"{res['within60']:.1%} / {res['within10']:.1%}"),
        ("beam mass on segments' first frames (median)", f"{res['first_mass']:.1%}"),
        ("segments passing the entry test (median; p10-p90)",
         f"{res['entrants']:.0f} ({res['entrants_p10']:.0f}-{res['entrants_p90']:.0f})"),
        ("segments in the entrants' balls / neither entrant nor in the beam (all steps)",
         f"{res['ball_found']:.0f} / {res['ball_extra']:.0f}"),
        (f"compiled step, beam {width} (µs CPU)", f"{res['beam_step']:.0f}"),
        ("compiled step, exact (µs CPU)", f"{res['exact_step']:.0f}"),
        ("cKDTree: nearest first frame of each block (µs)", f"{res['ckd_nearest']:.0f}"),
        ("cKDTree: ball of each block (µs)", f"{res['ckd_ball']:.0f}"),
        ("cKDTree: empty ball of each block, the calls alone (µs)", f"{res['ckd_call']:.0f}"),
        ("sklearn KDTree: nearest first frame of each block (µs)", f"{res['skl_nearest']:.0f}"),
        ("sklearn KDTree: ball of each block (µs)", f"{res['skl_ball']:.0f}"),
    ]
    head = (f"mousas2017 at {frames} database frames ({res['states']:.0f} frame states, "
            f"{res['segments']:.0f} segments in {res['blocks']:.0f} blocks), beam {width}:")
    return "\n".join([head, "", "| per step | value |", "|---|---:|"]
                     + [f"| {k} | {v} |" for k, v in rows]) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=Path("../shared/data/bandai-namco-2"))
    ap.add_argument("--db-frames", type=int, default=100_000)
    ap.add_argument("--width", type=int, default=2048)
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("-o", type=Path, default=None, help="write the table here too")
    args = ap.parse_args()
    out = check_output(args.o) if args.o else None
    with threadpool_limits(1):
        model, signals = fitted_model(args.data, args.db_frames)
        text = table(measure(model, signals, args.width, args.steps), args.db_frames,
                     args.width)
    print(text)
    if out is not None:
        with atomic_write(out, "w") as f:
            f.write(text)


if __name__ == "__main__":
    main()
