"""Readers of real inertial recordings that come with a gait reference.

Three layouts (``../shared/data/real-imu``, see its README), detected from a folder's files by
:func:`detect_layout`:

- ``pyshoe-vicon``: ``*_LLIO.mat``, one shoe-top IMU (200 Hz) with the foot's Vicon path and
  the sample index of every stride's end (foot flat).
- ``ipol-gait``: ``S-T.json`` with ``S-T_{lf,rf,lb}.txt``, Xsens IMUs on both feet and the lower
  back (100 Hz, each sample at its PacketCounter: the wireless sensors drop packets),
  hand-checked foot-off / foot-strike events, two straight 10 m bouts.
- ``mobilise-d-lab``: ``lab/{cohort}/{id}/data.mat``, a lower-back IMU (100 Hz) with the INDIP
  multi-sensor reference's walking bouts (initial contacts, stride lengths, speeds).

Each trial becomes a :class:`RealTrial`: a :class:`~imuloco.core.recording.Recording` in m/s²
and rad/s in the sensor's own axes (placements ``right_foot``, ``left_foot``, ``lower_back``)
and a :class:`GaitReference` in seconds and metres on the recording's time line, which
declares how its reference defines stride, speed, cadence and steps (:class:`GaitDefinition`).
"""

from __future__ import annotations

import contextlib
import faulthandler
import json
import os
import signal
import time
import warnings
from collections.abc import Iterator
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path

import numpy as np
from scipy.io import loadmat

from imuloco.core.recording import Recording
from imuloco.errors import FormatError, UnknownNameError, excerpt
from imuloco.io.xsens import stated_rate, unwrap_counter
from imuloco.ops.filters import resample_linear

G = 9.80665  # standard gravity, m/s^2 (mobilise-d-lab stores acceleration in g)
LAYOUTS = ("pyshoe-vicon", "ipol-gait", "mobilise-d-lab")
IPOL_BOUT_M = 10.0  # ipol-gait protocol: each straight bout is 10 m (Voisard et al. 2023)
IPOL_SENSORS = {"rf": "right_foot", "lf": "left_foot", "lb": "lower_back"}
IPOL_MAX_GAP = 1000  # packets: the longest run of dropped packets in ipol-gait is 65


@dataclass
class Bout:
    """A straight walking bout of the reference.

    start, end : seconds from the recording's first sample.
    distance_m : distance walked in it when the protocol fixes it (ipol-gait: 10 m), else NaN.
    strides : reference number of strides (NaN when unknown).
    cadence_spm, stride_length_m, speed_mps : the reference's means over the bout (NaN when
        the reference does not give them).
    """

    start: float
    end: float
    distance_m: float = float("nan")
    strides: float = float("nan")
    cadence_spm: float = float("nan")
    stride_length_m: float = float("nan")
    speed_mps: float = float("nan")


class GaitDefinition(Enum):
    """How a reference defines its bouts' stride, speed and cadence and which window its step
    count covers (what :func:`imuloco.lab.real.evaluate_gait` measures the estimate by)."""

    BOUT_MEANS = "bout-means"
    """The reference's own per-bout means, steps from its contacts inside its bouts:
    mobilise-d-lab's INDIP, which measures every stride of its walking bouts."""
    DISTANCE_OVER_STEPS = "distance-over-steps"
    """The bout's fixed distance over all its steps and its time from the first foot-off, cadence
    from its contacts' span, steps over the whole trial (turn included, the strikes annotated
    after its end left out): ipol-gait, which measures no distance but the course's 10 m."""
    STRIDES_OVER_TRIAL = "strides-over-trial"
    """Strides from foot flat to foot flat counted over the whole trial, pauses included, with its
    distance and time, steps between the first and last foot flat: pyshoe-vicon, whose Vicon
    positions are known at the stride ends only."""


@dataclass
class GaitReference:
    """What a real recording's reference measured (times in seconds from its first sample).

    initial_contacts : per foot (``left``, ``right``, or ``any`` when the side is unknown),
        ndarray (K,) of initial-contact times.
    final_contacts : per foot, ndarray (K,) of final-contact (foot-off) times, when the
        reference has them (ipol-gait).
    bouts : straight walking bouts with their reference summaries.
    stride_ends : ndarray (K,), times of the foot-flat samples that end each stride of the
        sensor's foot (pyshoe-vicon), or None.
    stride_points : ndarray (K, 2), the foot's reference floor position at those times, metres.
    path_times, path : ndarray (N,) and (N, 2), the foot's reference path (Vicon), or None.
    published_path : ndarray (N, 2), another published estimate of that path (PyShoe's), or
        None.
    path_z_down : the reference's floor coordinates are those of a frame whose z points down
        (pyshoe-vicon's: its IMU reads -9.8 on z at rest), mirror images of a z-up frame's.
    height_m : the walker's body height, NaN when unknown.
    sensor_height_m : height of a lower-back sensor above the floor, NaN when unknown.
    source : the reference system, e.g. ``"Vicon"``, ``"hand-checked events"``, ``"INDIP"``.
    definition : how the reference defines the bouts' figures and the steps.
    """

    initial_contacts: dict[str, np.ndarray] = field(default_factory=dict)
    final_contacts: dict[str, np.ndarray] = field(default_factory=dict)
    bouts: list[Bout] = field(default_factory=list)
    stride_ends: np.ndarray | None = None
    stride_points: np.ndarray | None = None
    path_times: np.ndarray | None = None
    path: np.ndarray | None = None
    published_path: np.ndarray | None = None
    path_z_down: bool = False
    height_m: float = float("nan")
    sensor_height_m: float = float("nan")
    source: str = ""
    definition: GaitDefinition = GaitDefinition.BOUT_MEANS


@dataclass
class RealTrial:
    """One recording of a real data set with its reference."""

    dataset: str
    name: str
    recording: Recording
    reference: GaitReference


def detect_layout(folder: str | Path) -> str:
    """Which of :data:`LAYOUTS` a folder holds, from its files (FormatError if none)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise FormatError(folder, None, "not a folder")
    if next(folder.glob("*_LLIO.mat"), None) is not None:
        return "pyshoe-vicon"
    if next(folder.glob("*_lb.txt"), None) is not None:
        return "ipol-gait"
    if next(folder.glob("lab/*/*/data.mat"), None) is not None:
        return "mobilise-d-lab"
    raise FormatError(folder, None, "no real-data layout found (expected *_LLIO.mat "
                      "(pyshoe-vicon), S-T_lb.txt with S-T.json (ipol-gait) or "
                      "lab/COHORT/ID/data.mat (mobilise-d-lab))")


def find_datasets(folder: str | Path) -> list[tuple[str, Path]]:
    """``(layout, folder)`` of ``folder`` itself or of its sub-folders that hold a layout."""
    folder = Path(folder)
    try:
        return [(detect_layout(folder), folder)]
    except FormatError:
        pass
    found = []
    for sub in sorted(p for p in folder.iterdir() if p.is_dir()) if folder.is_dir() else []:
        try:
            found.append((detect_layout(sub), sub))
        except FormatError:
            continue
    if not found:
        raise FormatError(folder, None, f"neither it nor its sub-folders hold a real-data layout "
                          f"({', '.join(LAYOUTS)})")
    return found


def read_trials(folder: str | Path, layout: str | None = None, limit: int | None = None
                ) -> Iterator[RealTrial]:
    """The trials of one data set folder, sorted by name (at most ``limit``)."""
    layout = layout or detect_layout(folder)
    readers = {"pyshoe-vicon": (read_pyshoe, "*_LLIO.mat"),
               "ipol-gait": (read_ipol, "*.json"),
               "mobilise-d-lab": (read_mobilise, "lab/*/*/data.mat")}
    if layout not in readers:
        raise UnknownNameError(f"unknown real-data layout {layout!r}; expected one of {LAYOUTS}")
    reader, pattern = readers[layout]
    paths = sorted(Path(folder).glob(pattern))[:limit]
    if not paths:
        raise FormatError(folder, None, f"no {pattern} in it ({layout} has one per trial)")
    for path in paths:
        yield from reader(path)


LOADMAT_TIMEOUT_S = 30.0  # seconds a MAT file's trial read may take, besides 2 s a megabyte


def _loadmat(path: Path, **kw) -> dict:
    """``scipy.io.loadmat``, or a FormatError for a file it cannot read.

    scipy's MAT reader is not hardened against damaged files (its docstring says so): some
    crash the process (a segmentation fault on an out-of-range element type, scipy PR
    25349). A forked child reads the file first and only its exit status is looked at (no
    data comes back from it), which costs one more read (30 ms for a mobilise-d-lab file). A
    child still reading after :data:`LOADMAT_TIMEOUT_S` (plus 2 s a megabyte) is killed and the
    file refused, so that no file can hang the program."""
    if hasattr(os, "fork"):
        with warnings.catch_warnings():  # Python 3.12+ warns of fork in a threaded process:
            warnings.simplefilter("ignore", DeprecationWarning)  # the child takes no lock
            pid = os.fork()
        if pid == 0:
            try:
                faulthandler.disable()  # a crash is the expected outcome, not to be reported
                with contextlib.suppress(Exception):  # only a crash (a signal) is looked for
                    loadmat(path, **kw)
            finally:
                os._exit(0)
        limit = LOADMAT_TIMEOUT_S + 2.0 * path.stat().st_size / 1e6
        deadline = time.monotonic() + limit
        while not (done := os.waitpid(pid, os.WNOHANG))[0]:
            if time.monotonic() > deadline:
                os.kill(pid, signal.SIGKILL)
                os.waitpid(pid, 0)
                raise FormatError(path, None, f"not a readable MATLAB v5 file (scipy's reader "
                                  f"was still reading it after {limit:.0f} s)")
            time.sleep(0.005)
        status = done[1]
        if os.WIFSIGNALED(status):
            raise FormatError(path, None, f"not a readable MATLAB v5 file (scipy's reader "
                              f"crashed on it with signal {os.WTERMSIG(status)})")
    try:
        return loadmat(path, **kw)
    except Exception as e:  # noqa: BLE001 - scipy's MAT reader raises anything on damaged
        # bytes (TypeError "Expecting miMATRIX", KeyError, UnboundLocalError, MemoryError, ...)
        raise FormatError(path, None, f"not a readable MATLAB v5 file "
                          f"({type(e).__name__}: {e})") from None


def _read_json(path: Path) -> object:
    try:
        return json.loads(path.read_bytes().decode("utf-8"))
    except (ValueError, RecursionError) as e:  # JSONDecodeError, UnicodeDecodeError
        raise FormatError(path, None, f"not JSON ({type(e).__name__}: {e})") from None


def _numbers(value, path: Path, name: str, expected: str, shape: tuple[int | None, ...] = (),
             finite: bool = True) -> np.ndarray:
    """``value`` (a MATLAB variable, a struct field or a JSON value) as a float array of
    ``shape`` (None: any length), or a FormatError naming ``name`` and ``expected``."""
    try:
        a = np.asarray(value)
    except ValueError:  # a ragged JSON list
        a = np.empty(0, dtype=object)
    ok = (a.dtype.kind in "iuf" and a.ndim == len(shape)
          and all(n is None or n == m for n, m in zip(shape, a.shape)))
    if ok and finite:
        ok = bool(np.isfinite(a).all())
    if not ok:
        raise FormatError(path, None, f"{name}: expected {expected}, got {a.dtype.name} "
                          f"{a.shape}: {excerpt(' '.join(str(value).split()))}")
    return a.astype(np.float64)


def _struct(v, path: Path, where: str, keys: tuple[str, ...] = ()) -> dict:
    """``v`` if it is a MATLAB struct or a JSON object (a dict) with ``keys``, else a
    FormatError naming ``where``."""
    if not isinstance(v, dict):
        fields = f" of fields {', '.join(keys)}" if keys else ""
        raise FormatError(path, None, f"{where}: expected a struct{fields}, got "
                          f"{type(v).__name__} {excerpt(v)}")
    missing = [k for k in keys if k not in v]
    if missing:
        raise FormatError(path, None, f"{where}: missing field {missing[0]!r}")
    return v


def _field(d: dict, key: str, path: Path, shape: tuple[int | None, ...] = (None, None),
           finite: bool = True) -> np.ndarray:
    if key not in d:
        raise FormatError(path, None, f"missing field {key!r}")
    return _numbers(d[key], path, f"field {key!r}", f"a {len(shape)}-D array of finite numbers "
                    f"of shape ({', '.join('N' if n is None else str(n) for n in shape)})", shape,
                    finite)


def read_pyshoe(path: str | Path) -> Iterator[RealTrial]:
    """One ``*_LLIO.mat`` of pyshoe-vicon: ``imu_data`` (N, 6) acc m/s² then gyro rad/s,
    ``timestamps_all`` s, ``gt`` (N, 2) Vicon path, ``strideIndex`` stride-end samples (1-based
    MATLAB indices are not assumed: the file's values are used as 0-based sample indices, as
    the LLIO code does), ``GCP`` (K, 2) Vicon positions there, ``pyshoeTrajectory`` (N, 2)."""
    path = Path(path)
    d = _loadmat(path)
    imu = _field(d, "imu_data", path, (None, 6))
    # the SensorConnectData files name it ``timestamps`` and have no full Vicon path ``gt``
    t = _field(d, "timestamps_all" if "timestamps_all" in d else "timestamps", path).ravel()
    if len(t) != len(imu) or len(t) < 2:
        raise FormatError(path, None, f"expected as many timestamps as imu_data's {len(imu)} "
                          f"samples (two or more), got {len(t)}")
    if not np.all(np.diff(t) > 0):
        raise FormatError(path, None, f"timestamps: expected increasing times, got "
                          f"{t[1:][np.diff(t) <= 0][0]} after {t[:-1][np.diff(t) <= 0][0]}")
    t = t - t[0]
    idx = _field(d, "strideIndex", path).ravel()
    if len(idx) < 2 or idx.min() < 0 or idx.max() > len(t) or np.any(np.diff(idx) <= 0):
        raise FormatError(path, None, f"strideIndex: expected at least two increasing sample "
                          f"indices in 0-{len(t)}, got {idx[:6].tolist()}")
    idx = np.clip(idx.astype(np.int64), 0, len(t) - 1)
    if idx[-1] == idx[0]:  # e.g. [0.2, 0.7]: a bout of no time
        raise FormatError(path, None, f"strideIndex: expected the first and last stride ends "
                          f"on different samples, got {idx[:6].tolist()}")
    gcp = _field(d, "GCP", path, (None, 2))
    rec = Recording(t, imu[:, None, :3], imu[:, None, 3:], ["right_foot"])
    # one bout from the first foot flat to the last, pauses included
    start, end, strides = float(t[idx[0]]), float(t[idx[-1]]), float(len(idx) - 1)
    dist = float(np.linalg.norm(np.diff(gcp, axis=0), axis=-1).sum())
    ref = GaitReference(
        stride_ends=t[idx], stride_points=gcp, path_times=t,
        path=_field(d, "gt", path, (None, 2), finite=False) if "gt" in d else None,
        published_path=(_field(d, "pyshoeTrajectory", path, (None, 2), finite=False)
                        if "pyshoeTrajectory" in d else None),
        bouts=[Bout(start, end, dist, strides, cadence_spm=120.0 * strides / (end - start),
                    stride_length_m=dist / strides, speed_mps=dist / (end - start))],
        path_z_down=True, source="Vicon", definition=GaitDefinition.STRIDES_OVER_TRIAL)
    yield RealTrial("pyshoe-vicon", path.name.removesuffix("_LLIO.mat"), rec, ref)


def _read_ipol_txt(path: Path) -> tuple[float, np.ndarray, np.ndarray]:
    """Rate (Hz), the (N,) packet counters and the (N, 6) acc m/s², gyro rad/s columns of an
    ipol-gait ``.txt``."""
    if not path.is_file():
        raise FormatError(path, None, "missing (ipol-gait has S-T_lf, _rf and _lb beside S-T.json)")
    with path.open("rb") as fh:
        first = fh.readline().decode("utf-8", "replace")
        body = fh.readline() and fh.readline()  # the first sample's line, if any
    rate = stated_rate(first) or float("nan")
    if not 1.0 <= rate <= 1000.0:
        raise FormatError(path, 1, f"expected 'Acquisition frequency: 100 Hz' (1-1000 Hz), got "
                          f"{excerpt(first)}")
    if not body.strip():
        raise FormatError(path, 3, "no samples after the two header lines")
    try:
        data = np.loadtxt(path, skiprows=2, delimiter="\t", ndmin=2, encoding="utf-8")
    except ValueError as e:  # UnicodeDecodeError included
        raise FormatError(path, None, f"not tab-separated numbers after the header ({e})") from None
    if data.shape[1] < 7:
        raise FormatError(path, None, f"expected PacketCounter, Acc_X..Z, Gyr_X..Z columns, got "
                          f"{data.shape[1]}")
    bad = ~np.isfinite(data[:, :7]).all(axis=1) | (data[:, 0] < 0) | (data[:, 0] > 65535)
    if bad.any():
        row = int(np.flatnonzero(bad)[0])
        raise FormatError(path, row + 3, f"expected a PacketCounter in 0-65535 (Xsens's 16-bit "
                          f"counter) and finite Acc, Gyr, got {data[row, :7].tolist()}")
    counter = unwrap_counter(data[:, 0])
    step = np.diff(counter)
    if np.any(step < 0) or np.any(step > IPOL_MAX_GAP):
        row = int(np.flatnonzero((step < 0) | (step > IPOL_MAX_GAP))[0]) + 4  # 1-based
        raise FormatError(path, row, "PacketCounter goes back" if step[row - 4] < 0 else
                          f"PacketCounter jumps by {step[row - 4]:.0f} packets (dropped runs "
                          f"up to {IPOL_MAX_GAP} expected)")
    # a packet sent twice (one in the data set) keeps its first copy
    counter, first = np.unique(counter, return_index=True)
    if len(counter) < 2:
        raise FormatError(path, None, "fewer than two samples")
    return rate, counter, data[first, 1:7]


def read_ipol(path: str | Path) -> Iterator[RealTrial]:
    """One ipol-gait trial from its ``S-T.json`` and the three ``.txt`` beside it."""
    path = Path(path)
    keys = ("TrialBoundaries", "UTurnBoundaries", "LeftFootEvents", "RightFootEvents", "Height")
    meta = _struct(_read_json(path), path, "top level", keys)
    # sample numbers: [start, end] of the trial and of its U-turn, [foot-off, foot-strike] per
    # swing; the height in cm
    bounds = [_numbers(meta[k], path, k, "[first, last] sample numbers", (2,))
              for k in keys[:2]]
    events = {}
    for side in ("left", "right"):
        key = f"{side.title()}FootEvents"
        events[side] = _numbers(np.zeros((0, 2)) if meta[key] == [] else meta[key], path, key,
                                "[[foot-off, foot-strike], ...] sample numbers", (None, 2))
    height = _numbers(np.nan if meta["Height"] is None else meta["Height"], path, "Height",
                      "a height in cm (NaN or null when unknown)", finite=False)
    (start, end), (u0, u1) = bounds
    if not start < u0 <= u1 < end or not (np.isnan(height) or 0 < height < 300):
        raise FormatError(path, None, f"expected TrialBoundaries [start, end] around "
                          f"UTurnBoundaries and a Height in cm, got {meta['TrialBoundaries']}, "
                          f"{meta['UTurnBoundaries']} and {meta['Height']}")
    stem = path.stem
    read = [_read_ipol_txt(path.with_name(f"{stem}_{key}.txt")) for key in IPOL_SENSORS]
    rate = read[0][0]
    if any(r != rate for r, _, _ in read):
        raise FormatError(path, None, f"the three sensors have different rates "
                          f"{[r for r, _, _ in read]}")
    # The wireless sensors drop packets (up to 12 % of a trial, runs of up to 65): a row is
    # not a sample period. Each sample sits at its PacketCounter, the time base the reference
    # events are counted in, and the three sensors are put on that common grid, the dropped
    # packets linearly interpolated.
    first = max(c[0] for _, c, _ in read)
    last = min(c[-1] for _, c, _ in read)
    if last - first < 1:
        raise FormatError(path, None, f"the PacketCounters of {stem}_{{lf,rf,lb}}.txt do not "
                          f"overlap (first {[float(c[0]) for _, c, _ in read]}, "
                          f"last {[float(c[-1]) for _, c, _ in read]})")
    grid = np.arange(first, last + 1)
    arr = np.stack([resample_linear(c, d, grid) for _, c, d in read], axis=1)  # (N, 3, 6)
    t = grid / rate
    rec = Recording(t, arr[..., :3], arr[..., 3:], list(IPOL_SENSORS.values()))
    start, end, u0, u1 = (v / rate for v in (start, end, u0, u1))
    events = {side: e / rate for side, e in events.items()}  # [foot-off, foot-strike] per swing
    ics = {side: e[:, 1] for side, e in events.items()}
    bouts = []
    for a, b in ((start, u0), (u1, end)):
        # strides of the bout: swings of both feet that end inside it, two steps a stride
        steps = sum(int(np.sum((v >= a) & (v <= b))) for v in ics.values())
        bouts.append(Bout(a, b, IPOL_BOUT_M, strides=steps / 2.0,
                          cadence_spm=60.0 * steps / (b - a),
                          stride_length_m=2.0 * IPOL_BOUT_M / steps if steps else float("nan"),
                          speed_mps=IPOL_BOUT_M / (b - a)))
    ref = GaitReference(initial_contacts=ics, bouts=bouts,
                        final_contacts={side: e[:, 0] for side, e in events.items()},
                        height_m=float(height) / 100,
                        source="hand-checked events, 10 m bouts",
                        definition=GaitDefinition.DISTANCE_OVER_STEPS)
    yield RealTrial("ipol-gait", stem, rec, ref)


def _as_list(v) -> list:
    """A MATLAB struct array as loaded with ``simplify_cells``: list, one dict or empty."""
    if isinstance(v, list):
        return v
    return [v] if isinstance(v, dict) else []


def _wb_bout(wb: dict, path: Path, where: str) -> Bout:
    keys = ("Start", "End", "NumberStrides", "Cadence", "AverageStrideLength", "WalkingSpeed")
    wb = _struct(wb, path, where, keys + ("InitialContact_Event",))
    v = {k: float(_numbers(wb[k], path, f"{where}.{k}", "a number", finite=k in keys[:2]))
         for k in keys}
    length = np.ravel(_numbers(np.ravel(wb.get("Length", np.nan)), path, f"{where}.Length",
                               "a number", (None,), finite=False))
    if not v["End"] > v["Start"]:
        raise FormatError(path, None, f"{where}: expected End > Start, got {v['Start']} and "
                          f"{v['End']}")
    return Bout(v["Start"], v["End"], strides=v["NumberStrides"], cadence_spm=v["Cadence"],
                stride_length_m=v["AverageStrideLength"], speed_mps=v["WalkingSpeed"],
                distance_m=float(length[0]) if len(length) == 1 else float("nan"))


def read_mobilise(path: str | Path, standard: str = "INDIP") -> Iterator[RealTrial]:
    """The trials of one mobilise-d-lab participant (``lab/COHORT/ID/data.mat``): each test's
    trial with a lower-back recording and a ``standard`` reference (INDIP or Stereophoto)."""
    path = Path(path)
    data = _loadmat(path, simplify_cells=True)
    if "data" not in data:
        raise FormatError(path, None, "missing field 'data'")
    cohort, pid = path.parent.parent.name, path.parent.name
    meta_path = path.parent.parent.parent.parent / "participant_metadata.json"
    meta = {}
    if meta_path.is_file():
        meta = _read_json(meta_path)
        for key in (cohort, pid):
            meta = _struct(meta, meta_path, f"{cohort}.{pid}").get(key, {})
        _struct(meta, meta_path, f"{cohort}.{pid}")
    heights = [float(_numbers(np.nan if meta.get(k) is None else meta[k], meta_path,
                              f"{cohort}.{pid}.{k}", "metres", finite=False))
               for k in ("height_m", "sensor_height_m")]
    for tm_name, tm in _struct(data["data"], path, "data").items():
        for test_name, test in _struct(tm, path, f"data.{tm_name}").items():
            where = f"data.{tm_name}.{test_name}"
            for trial_name, trial in _struct(test, path, where).items():
                trial = _struct(trial, path, f"{where}.{trial_name}")
                su = _struct(trial.get("SU", {}), path, f"{where}.{trial_name}.SU")
                stds = _struct(trial.get("Standards", {}), path,
                               f"{where}.{trial_name}.Standards")
                if "LowerBack" not in su or standard not in stds:
                    continue  # no lower-back recording or no such reference
                at = f"{where}.{trial_name}.SU.LowerBack"
                lb = _struct(su["LowerBack"], path, at, ("Acc", "Gyr", "Fs"))
                std = _struct(stds[standard], path, f"{where}.{trial_name}.Standards.{standard}")
                acc = _numbers(lb["Acc"], path, f"{at}.Acc", "(N, 3) finite g", (None, 3)) * G
                gyro = np.radians(_numbers(lb["Gyr"], path, f"{at}.Gyr",
                                           f"({len(acc)}, 3) finite deg/s", (len(acc), 3)))
                fs = lb["Fs"]["Acc"] if isinstance(lb["Fs"], dict) and "Acc" in lb["Fs"] else (
                    _as_list(lb["Fs"]) or [lb["Fs"]])[0]
                fs = float(_numbers(fs, path, f"{at}.Fs", "a rate in Hz"))
                if not 1.0 <= fs <= 1000.0 or len(acc) < 2:
                    raise FormatError(path, None, f"{at}: expected a rate of 1-1000 Hz and two "
                                      f"samples or more, got {fs} Hz and {len(acc)}")
                t = np.arange(len(acc)) / fs
                at = f"{where}.{trial_name}.Standards.{standard}.MicroWB"
                wbs = [_wb_bout(w, path, at) for w in _as_list(std.get("MicroWB"))]
                if not wbs:
                    continue  # no walking bout in the reference
                ics = np.concatenate([_numbers(np.atleast_1d(w["InitialContact_Event"]), path,
                                               f"{at}.InitialContact_Event", "seconds", (None,),
                                               finite=False) for w in _as_list(std["MicroWB"])])
                ref = GaitReference(initial_contacts={"any": ics[np.isfinite(ics)]},
                                    bouts=wbs, height_m=heights[0], sensor_height_m=heights[1],
                                    source=standard, definition=GaitDefinition.BOUT_MEANS)
                rec = Recording(t, acc[:, None], gyro[:, None], ["lower_back"])
                yield RealTrial("mobilise-d-lab", f"{cohort}-{pid}-{test_name}-{trial_name}",
                                rec, ref)
