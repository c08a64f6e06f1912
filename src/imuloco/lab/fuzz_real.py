"""The ``real`` reader kind of ``imuloco bench --fuzz``: the real-data layouts of
:mod:`imuloco.io.realimu`, read with :func:`~imuloco.io.realimu.read_trials`.

Seeds are small valid folders of the three layouts (a file name may hold ``/``: the folder's
own tree): ``pyshoe-vicon`` (``a_LLIO.mat``), ``ipol-gait`` (``1-1.json`` with tab-separated
``1-1_{lf,rf,lb}.txt``) and ``mobilise-d-lab`` (``participant_metadata.json`` with
``lab/HA/001/data.mat``). The structured attacks rebuild a seed with one part broken: a MATLAB
variable or struct field of the wrong type or shape (text, empty, a struct, NaN/inf, 1e300,
3-D), an ipol-gait JSON field of the wrong type (null, text, ragged, reversed, NaN), a
PacketCounter that goes back, jumps by 1e15 or is NaN, a rate of 0/-100/NaN Hz, cells that are
not numbers, sensors whose counters do not overlap, an empty or truncated file, a companion file
missing.
"""

from __future__ import annotations

import io
import json
import os
import random
from pathlib import Path

import numpy as np
from scipy.io import savemat

from imuloco.io.realimu import detect_layout, read_trials
from imuloco.lab.mutations import Files

PYSHOE = "a_LLIO.mat"
IPOL = "1-1"
MOBILISE = "lab/HA/001/data.mat"
MOBILISE_META = "participant_metadata.json"
IPOL_HEADER = ("Acquisition frequency: 100 Hz\nPacketCounter\tAcc_X\tAcc_Y\tAcc_Z\tGyr_X\tGyr_Y"
               "\tGyr_Z\tMag_X\tMag_Y\tMag_Z\n")
# what a broken variable or field becomes
BAD_VALUES = ("text", "empty", "struct", "cell", "nan", "inf", "huge", "negative", "3-D",
              "row", "one", "complex", "bool")


def _savemat(variables: dict) -> bytes:
    buf = io.BytesIO()
    savemat(buf, variables)
    return buf.getvalue()


def _pyshoe_vars(n: int = 200) -> dict:
    t = np.arange(n) / 200.0
    imu = np.zeros((n, 6))
    imu[:, 2] = -9.81
    imu[:, 3] = np.sin(t * 6)
    path = np.stack([t, 0 * t], 1)
    return {"imu_data": imu, "timestamps_all": t[None], "gt": path,
            "strideIndex": np.array([[10, 100, 190]]), "GCP": path[[10, 100, 190]],
            "pyshoeTrajectory": path}


def _ipol_meta() -> dict:
    return {"Height": 170, "TrialBoundaries": [5, 55], "UTurnBoundaries": [25, 30],
            "LeftFootEvents": [[8, 12], [35, 40]], "RightFootEvents": [[14, 18], [42, 47]]}


def _ipol_txt(counters: list[float], header: str = IPOL_HEADER) -> bytes:
    rows = [f"{c!r}\t0.1\t0.2\t9.81\t{0.01 * i:.6f}\t0\t0\t-0.3\t0.07\t-0.8"
            for i, c in enumerate(counters)]
    return (header + "\n".join(rows) + "\n").encode()


def _mobilise_vars(n: int = 300) -> dict:
    acc = np.zeros((n, 3))
    acc[:, 0] = 1.0  # g
    wb = {"Start": 0.5, "End": 2.5, "NumberStrides": 2.0, "Cadence": 100.0,
          "AverageStrideLength": 1.2, "WalkingSpeed": 1.0, "Length": 2.4,
          "InitialContact_Event": np.array([0.6, 1.1, 1.7, 2.2])}
    trial = {"SU": {"LowerBack": {"Acc": acc, "Gyr": np.zeros((n, 3)), "Fs": {"Acc": 100.0}}},
             "Standards": {"INDIP": {"MicroWB": np.array([wb, dict(wb, Start=2.6, End=2.9)],
                                                         dtype=object), "Fs": 100}}}
    return {"data": {"TimeMeasure1": {"Test5": {"Trial1": trial}}}}


def _mobilise_meta() -> dict:
    return {"HA": {"001": {"height_m": 1.7, "sensor_height_m": 0.95}}}


def real_seeds() -> list[Files]:
    """One small valid folder per layout (:data:`~imuloco.io.realimu.LAYOUTS`)."""
    ipol = {f"{IPOL}.json": json.dumps(_ipol_meta()).encode()}
    for key in ("lf", "rf", "lb"):
        ipol[f"{IPOL}_{key}.txt"] = _ipol_txt([float(c) for c in range(60)])
    return [{PYSHOE: _savemat(_pyshoe_vars())}, ipol,
            {MOBILISE_META: json.dumps(_mobilise_meta()).encode(),
             MOBILISE: _savemat(_mobilise_vars())}]


def _bad(kind: str, like) -> object:
    """``like`` (an array or number) broken as ``kind`` (one of :data:`BAD_VALUES`)."""
    try:
        a = np.asarray(like, dtype=float)
    except (TypeError, ValueError):  # a struct or a struct array
        a = np.zeros(3)
    return {"text": "walking", "empty": np.zeros((0, 0)), "struct": {"a": 1.0},
            "cell": np.array([1.0, "x"], dtype=object), "nan": np.full(a.shape, np.nan),
            "inf": np.full(a.shape, np.inf), "huge": np.full(a.shape, 1e300),
            "negative": -np.abs(a) - 1, "3-D": np.zeros((2, 2, 2)), "row": a.reshape(-1)[:5],
            "one": np.ones((1, 1)), "complex": a + 1j, "bool": a > 0}[kind]


def _set_path(tree: dict, keys: list[str], value) -> None:
    for k in keys[:-1]:
        tree = tree[k]
    tree[keys[-1]] = value


def _leaves(tree: dict, prefix: tuple = ()) -> list[list[str]]:
    """Key paths of every field of a nested dict (inner dicts included)."""
    out = []
    for k, v in tree.items():
        out.append([*prefix, k])
        if isinstance(v, dict):
            out += _leaves(v, (*prefix, k))
    return out


def real_attack(files: Files, rng: random.Random) -> tuple[str, Files]:
    """A structured attack on one of :func:`real_seeds`' folders (see the module docstring)."""
    files = dict(files)
    if PYSHOE in files:
        return _mat_attack(files, PYSHOE, _pyshoe_vars(), rng)
    if MOBILISE_META in files:
        kind = rng.choice(("mat", "mat", "mat", "microwb", "meta", "drop"))
        if kind == "drop":
            del files[MOBILISE]
            return "attack:drop-data.mat", files
        if kind == "meta":
            meta = rng.choice(("[]", "{", '{"HA": 3}', '{"HA": {"001": []}}',
                               '{"HA": {"001": {"height_m": "tall"}}}',
                               '{"HA": {"001": {"height_m": null, "sensor_height_m": -1}}}'))
            files[MOBILISE_META] = meta.encode()
            return f"attack:metadata {meta}", files
        variables = _mobilise_vars()
        if kind == "microwb":
            wb = dict(variables["data"]["TimeMeasure1"]["Test5"]["Trial1"]["Standards"]["INDIP"]
                      ["MicroWB"][0])
            key = rng.choice(sorted(wb) + ["(all)"])
            bad = rng.choice(BAD_VALUES)
            if key == "(all)":
                wb = {}
            else:
                wb[key] = _bad(bad, wb[key])
            _set_path(variables, ["data", "TimeMeasure1", "Test5", "Trial1", "Standards",
                                  "INDIP", "MicroWB"], np.array([wb], dtype=object))
            files[MOBILISE] = _savemat(variables)
            return f"attack:MicroWB.{key}={bad}", files
        return _mat_attack(files, MOBILISE, variables, rng)
    return _ipol_attack(files, rng)


def _mat_attack(files: Files, name: str, variables: dict, rng: random.Random
                ) -> tuple[str, Files]:
    keys = rng.choice(_leaves(variables))
    op = rng.choice(("bad", "bad", "bad", "drop", "truncate"))
    if op == "truncate":
        data = files[name]
        files[name] = data[: rng.randrange(len(data))]
        return "attack:truncate", files
    if op == "drop":
        _set_path(variables, keys, None)
        tree = variables
        for k in keys[:-1]:
            tree = tree[k]
        del tree[keys[-1]]
        if not variables:
            variables = {"x": 1.0}
        files[name] = _savemat(variables)
        return f"attack:drop {'.'.join(keys)}", files
    tree = variables
    for k in keys[:-1]:
        tree = tree[k]
    bad = rng.choice(BAD_VALUES)
    tree[keys[-1]] = _bad(bad, tree[keys[-1]])
    if keys == ["timestamps_all"] and rng.random() < 0.5:  # times that go back or stand still
        t = _pyshoe_vars()["timestamps_all"].copy()
        bad = rng.choice(("reversed", "constant", "short"))
        tree[keys[-1]] = {"reversed": t[:, ::-1], "constant": 0 * t, "short": t[:, :50]}[bad]
    files[name] = _savemat(variables)
    return f"attack:{'.'.join(keys)}={bad}", files


IPOL_JSON_VALUES = (None, "x", [], [1], [1, 2, 3], [[1, 2], [3]], {"a": 1}, 1e308, -5,
                    float("nan"), [1e30, 1e31], [55, 5], [0, 0], True, [[1, 2, 3]], ["a", "b"])


def _ipol_attack(files: Files, rng: random.Random) -> tuple[str, Files]:
    kind = rng.choice(("json-field", "json-field", "json-type", "drop", "counter", "counter",
                       "rate", "columns", "cell", "empty", "lengths"))
    key = rng.choice(("lf", "rf", "lb"))
    txt = f"{IPOL}_{key}.txt"
    counters = [float(c) for c in range(60)]
    if kind == "json-field":
        meta = _ipol_meta()
        field = rng.choice(sorted(meta))
        meta[field] = rng.choice(IPOL_JSON_VALUES)
        files[f"{IPOL}.json"] = json.dumps(meta).encode()
        return f"attack:json {field}={meta[field]!r}", files
    if kind == "json-type":
        text = rng.choice(("[]", "3", "null", '"x"', "[" * 100_000 + "]" * 100_000, "{"))
        files[f"{IPOL}.json"] = text.encode()
        return f"attack:json {text[:10]}", files
    if kind == "drop":
        name = rng.choice(sorted(files))
        del files[name]
        return f"attack:drop {name}", files
    if kind == "counter":
        how = rng.choice(("back", "jump", "nan", "negative", "wrap", "constant", "huge", "inf"))
        k = rng.randrange(1, len(counters))
        if how == "back":
            counters[k] = counters[k] - 10
        elif how == "jump":
            counters[k:] = [c + 1e15 for c in counters[k:]]
        elif how in ("nan", "inf"):
            counters[k] = float(how)
        elif how == "negative":
            counters = [c - 1e6 for c in counters]
        elif how == "wrap":
            counters = [(c + 65_500) % 65_536 for c in counters]
        elif how == "constant":
            counters = [7.0] * len(counters)
        else:
            counters = [c + 1e300 for c in counters]
        files[txt] = _ipol_txt(counters)
        return f"attack:counter {how} in {txt}", files
    if kind == "rate":
        rate = rng.choice(("0", "-100", "nan", "inf", "1e308", "1e-300", "x", ""))
        files[txt] = _ipol_txt(counters, IPOL_HEADER.replace("100 Hz", f"{rate} Hz"))
        return f"attack:rate {rate!r} in {txt}", files
    if kind == "columns":
        lines = files[txt].decode().splitlines()
        n = rng.choice((1, 3, 6, 7, 12))
        lines[2:] = ["\t".join(ln.split("\t")[:n] + ["0"] * max(0, n - 10)) for ln in lines[2:]]
        files[txt] = ("\n".join(lines) + "\n").encode()
        return f"attack:{n} columns in {txt}", files
    if kind == "cell":
        lines = files[txt].decode().splitlines()
        k = rng.randrange(2, len(lines))
        cells = lines[k].split("\t")
        cells[rng.randrange(len(cells))] = rng.choice(("x", "", "1,5", "nan", "1e309", "\x00"))
        lines[k] = "\t".join(cells)
        files[txt] = ("\n".join(lines) + "\n").encode()
        return f"attack:cell in {txt}", files
    if kind == "empty":
        files[txt] = rng.choice((b"", IPOL_HEADER.encode(), IPOL_HEADER.encode()[:30],
                                 _ipol_txt([0.0])))
        return f"attack:empty {txt}", files
    shift = rng.choice((30, 59, 100, 1000))  # one sensor's counters elsewhere
    files[txt] = _ipol_txt([c + shift for c in counters][: rng.choice((2, 10, 60))])
    return f"attack:lengths {txt} +{shift}", files


def read_real(paths: list[Path]) -> tuple[str, list]:
    """The layout and every trial of the folder that holds ``paths`` (the seed's root)."""
    root = Path(os.path.commonpath([p.parent for p in paths]))
    layout = detect_layout(root)
    return layout, list(read_trials(root, layout))


def real_garbage(result: tuple[str, list]) -> str | None:
    """Why trials read from a fuzzed folder are implausible, or ``None``: none at all (but
    from mobilise-d-lab, whose reader skips the trials without a lower-back recording and a
    reference walking bout, by design), a recording of fewer than 2 samples, with times that do not increase, a rate outside
    1-1000 Hz or non-finite values, or a reference with non-finite times or bouts that end
    before they start."""
    layout, trials = result
    if not trials and layout != "mobilise-d-lab":
        return "no trials"
    for trial in trials:
        rec, ref = trial.recording, trial.reference
        if rec.num_samples < 2 or not np.all(np.diff(rec.times) > 0):
            return f"{trial.name}: times not increasing"
        rate = 1.0 / float(np.median(np.diff(rec.times)))
        if not 1.0 <= rate <= 1000.0:
            return f"{trial.name}: rate {rate} Hz"
        if not (np.isfinite(rec.times).all() and np.isfinite(rec.channels()).all()):
            return f"{trial.name}: non-finite recording"
        events = [*ref.initial_contacts.values(), *ref.final_contacts.values()]
        if ref.stride_ends is not None:
            events += [ref.stride_ends, ref.stride_points]
        if not all(np.isfinite(e).all() for e in events):
            return f"{trial.name}: non-finite reference events"
        for b in ref.bouts:
            if not (np.isfinite([b.start, b.end]).all() and b.end > b.start):
                return f"{trial.name}: bout {b.start}-{b.end}"
    return None
