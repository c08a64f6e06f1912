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
and a :class:`GaitReference` in seconds and metres on the recording's time line.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from imuloco.core.recording import Recording
from imuloco.errors import FormatError, UnknownNameError
from imuloco.ops.filters import resample_linear

G = 9.80665  # standard gravity, m/s^2 (mobilise-d-lab stores acceleration in g)
LAYOUTS = ("pyshoe-vicon", "ipol-gait", "mobilise-d-lab")
IPOL_BOUT_M = 10.0  # ipol-gait protocol: each straight bout is 10 m (Voisard et al. 2023)
IPOL_SENSORS = {"rf": "right_foot", "lf": "left_foot", "lb": "lower_back"}


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
    for path in paths:
        yield from reader(path)


def _loadmat(path: Path, **kw) -> dict:
    from scipy.io import loadmat

    try:
        return loadmat(path, **kw)
    except (ValueError, OSError, NotImplementedError) as e:
        raise FormatError(path, None, f"not a readable MATLAB v5 file ({e})") from None


def _field(d: dict, key: str, path: Path) -> np.ndarray:
    if key not in d:
        raise FormatError(path, None, f"missing field {key!r}")
    return np.asarray(d[key], dtype=np.float64)


def read_pyshoe(path: str | Path) -> Iterator[RealTrial]:
    """One ``*_LLIO.mat`` of pyshoe-vicon: ``imu_data`` (N, 6) acc m/s² then gyro rad/s,
    ``timestamps_all`` s, ``gt`` (N, 2) Vicon path, ``strideIndex`` stride-end samples (1-based
    MATLAB indices are not assumed: the file's values are used as 0-based sample indices, as
    the LLIO code does), ``GCP`` (K, 2) Vicon positions there, ``pyshoeTrajectory`` (N, 2)."""
    path = Path(path)
    d = _loadmat(path)
    imu = _field(d, "imu_data", path)
    # the SensorConnectData files name it ``timestamps`` and have no full Vicon path ``gt``
    t = _field(d, "timestamps_all" if "timestamps_all" in d else "timestamps", path).ravel()
    if imu.ndim != 2 or imu.shape[1] != 6 or len(t) != len(imu):
        raise FormatError(path, None, f"imu_data must be (N, 6) with N timestamps, got "
                          f"{imu.shape} and {t.shape}")
    t = t - t[0]
    idx = _field(d, "strideIndex", path).ravel().astype(np.int64)
    idx = np.clip(idx, 0, len(t) - 1)
    gcp = _field(d, "GCP", path).reshape(-1, 2)
    rec = Recording(t, imu[:, None, :3], imu[:, None, 3:], ["right_foot"])
    ref = GaitReference(
        stride_ends=t[idx], stride_points=gcp, path_times=t,
        path=_field(d, "gt", path).reshape(-1, 2) if "gt" in d else None,
        published_path=(_field(d, "pyshoeTrajectory", path).reshape(-1, 2)
                        if "pyshoeTrajectory" in d else None),
        bouts=[Bout(float(t[idx[0]]), float(t[idx[-1]]),
                    float(np.linalg.norm(np.diff(gcp, axis=0), axis=-1).sum()),
                    strides=float(len(idx) - 1))],
        path_z_down=True, source="Vicon")
    yield RealTrial("pyshoe-vicon", path.name.removesuffix("_LLIO.mat"), rec, ref)


def _read_ipol_txt(path: Path) -> tuple[float, np.ndarray, np.ndarray]:
    """Rate (Hz), the (N,) packet counters and the (N, 6) acc m/s², gyro rad/s columns of an
    ipol-gait ``.txt``."""
    if not path.is_file():
        raise FormatError(path, None, "missing (ipol-gait has S-T_lf, _rf and _lb beside S-T.json)")
    with path.open() as fh:
        first = fh.readline()
    try:
        rate = float(first.split(":")[1].split()[0])
    except (IndexError, ValueError):
        raise FormatError(path, 1, f"expected 'Acquisition frequency: 100 Hz', got "
                          f"{first.strip()!r}") from None
    try:
        data = np.loadtxt(path, skiprows=2, delimiter="\t", ndmin=2)
    except ValueError as e:
        raise FormatError(path, None, f"not tab-separated numbers after the header ({e})") from None
    if data.shape[1] < 7:
        raise FormatError(path, None, f"expected PacketCounter, Acc_X..Z, Gyr_X..Z columns, got "
                          f"{data.shape[1]}")
    counter = _unwrap_counter(data[:, 0])
    if np.any(np.diff(counter) < 0):
        row = int(np.flatnonzero(np.diff(counter) < 0)[0]) + 4  # 1-based, two header lines
        raise FormatError(path, row, "PacketCounter goes back")
    # a packet sent twice (one in the data set) keeps its first copy
    counter, first = np.unique(counter, return_index=True)
    if len(counter) < 2:
        raise FormatError(path, None, "fewer than two samples")
    return rate, counter, data[first, 1:7]


def _unwrap_counter(counter: np.ndarray) -> np.ndarray:
    """Xsens's 16-bit PacketCounter made monotonic across its wrap at 65,536."""
    step = np.diff(counter)
    return counter[0] + np.concatenate([[0.0], np.cumsum(np.where(step < -32768, step + 65536,
                                                                  step))])


def read_ipol(path: str | Path) -> Iterator[RealTrial]:
    """One ipol-gait trial from its ``S-T.json`` and the three ``.txt`` beside it."""
    path = Path(path)
    try:
        meta = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise FormatError(path, None, f"not JSON ({e})") from None
    keys = ("TrialBoundaries", "UTurnBoundaries", "LeftFootEvents", "RightFootEvents", "Height")
    missing = [k for k in keys if k not in meta]
    if missing:
        raise FormatError(path, None, f"missing {missing}")
    stem = path.stem
    read = [_read_ipol_txt(path.with_name(f"{stem}_{key}.txt")) for key in IPOL_SENSORS]
    rate = read[0][0]
    if any(r != rate for r, _, _ in read):
        raise FormatError(path, None, f"the three sensors have different rates "
                          f"{[r for r, _, _ in read]}")
    # The wireless sensors drop packets (up to 12 % of a trial, runs of up to 10): a row is
    # not a sample period. Each sample sits at its PacketCounter, the time base the reference
    # events are counted in, and the three sensors are put on that common grid, the dropped
    # packets linearly interpolated.
    first = max(c[0] for _, c, _ in read)
    last = min(c[-1] for _, c, _ in read)
    grid = np.arange(first, last + 1)
    arr = np.stack([resample_linear(c, d, grid) for _, c, d in read], axis=1)  # (N, 3, 6)
    t = grid / rate
    rec = Recording(t, arr[..., :3], arr[..., 3:], list(IPOL_SENSORS.values()))
    start, end = (float(v) / rate for v in meta["TrialBoundaries"])
    u0, u1 = (float(v) / rate for v in meta["UTurnBoundaries"])
    events = {side: np.asarray(meta[f"{side.title()}FootEvents"], float).reshape(-1, 2) / rate
              for side in ("left", "right")}  # [foot-off, foot-strike] per swing
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
                        final_contacts={side: e[:, 0] for side, e in events.items()}, height_m=float(meta["Height"]) / 100,
                        source="hand-checked events, 10 m bouts")
    yield RealTrial("ipol-gait", stem, rec, ref)


def _as_list(v) -> list:
    """A MATLAB struct array as loaded with ``simplify_cells``: list, one dict or empty."""
    if isinstance(v, list):
        return v
    return [v] if isinstance(v, dict) else []


def _wb_bout(wb: dict) -> Bout:
    return Bout(float(wb["Start"]), float(wb["End"]), strides=float(wb["NumberStrides"]),
                cadence_spm=float(wb["Cadence"]),
                stride_length_m=float(wb["AverageStrideLength"]),
                speed_mps=float(wb["WalkingSpeed"]),
                distance_m=float(wb.get("Length", np.nan)))


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
        meta = json.loads(meta_path.read_text()).get(cohort, {}).get(pid, {})
    for tm in data["data"].values():
        for test_name, test in tm.items():
            for trial_name, trial in test.items():
                try:
                    lb = trial["SU"]["LowerBack"]
                    std = trial["Standards"][standard]
                except (KeyError, TypeError):
                    continue
                acc = np.asarray(lb["Acc"], float) * G
                gyro = np.radians(np.asarray(lb["Gyr"], float))
                fs = float(_as_list(lb["Fs"])[0] if not isinstance(lb["Fs"], dict)
                           else lb["Fs"]["Acc"])
                t = np.arange(len(acc)) / fs
                wbs = [_wb_bout(w) for w in _as_list(std.get("MicroWB"))]
                if not wbs:
                    continue  # no walking bout in the reference
                ics = np.concatenate([np.atleast_1d(np.asarray(w["InitialContact_Event"], float))
                                      for w in _as_list(std["MicroWB"])])
                ref = GaitReference(initial_contacts={"any": ics[np.isfinite(ics)]},
                                    bouts=wbs, height_m=float(meta.get("height_m", np.nan)),
                                    sensor_height_m=float(meta.get("sensor_height_m", np.nan)),
                                    source=standard)
                rec = Recording(t, acc[:, None], gyro[:, None], ["lower_back"])
                yield RealTrial("mobilise-d-lab", f"{cohort}-{pid}-{test_name}-{trial_name}",
                                rec, ref)
