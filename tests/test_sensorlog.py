"""Real sensor logs: parsers, cleaning, unit detection, gaps, and the RealWorld shin recording."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from imuloco.core.recording import Recording
from imuloco.errors import FormatError
from imuloco.io.logformats import detect_format
from imuloco.io.sensorlog import write_generic_csv
from imuloco.sensors.calibration import still_mask
from imuloco.sensors.reallog import read_log, recording_name
from imuloco.sensors.simulate import simulate


@pytest.fixture(scope="module")
def walk_rec(sample_db) -> Recording:
    """A phone on the right ankle during a sample walk: irregular timestamps, noise, drops."""
    return simulate(sample_db.where(content="walk").clips[0], ["right_ankle"], 100.0, "phone", 7)


def _shifted(rec: Recording) -> np.ndarray:
    return rec.times - rec.times[0]


def test_generic_round_trip(walk_rec, tmp_path):
    path = write_generic_csv(walk_rec, tmp_path / "rec.csv")
    assert path.read_text().splitlines()[0] == "time_s,acc_x,acc_y,acc_z,gyro_x,gyro_y,gyro_z"
    with pytest.raises(FileExistsError):
        write_generic_csv(walk_rec, path)
    back, report = read_log(path, rate=None)
    assert report.format == "generic" and back.placements == ["right_ankle"]
    assert (report.acc_unit, report.gyro_unit) == ("m/s^2", "rad/s")
    assert report.acc_unit_detected and report.gyro_unit_detected
    np.testing.assert_allclose(back.times, _shifted(walk_rec), atol=2e-6)
    np.testing.assert_allclose(back.acc, walk_rec.acc, rtol=1e-7, atol=1e-7)
    np.testing.assert_allclose(back.gyro, walk_rec.gyro, rtol=1e-7, atol=1e-7)
    # at the model rate: uniform, no NaN, same signal up to the light smoothing
    uni, _ = read_log(path, rate=100.0)
    assert uni.is_uniform() and np.isfinite(uni.channels()).all()
    assert abs(uni.rate - 100.0) < 1e-6


def test_multi_sensor_columns(sample_db, tmp_path):
    rec = simulate(sample_db.clips[0], ["right_ankle", "pelvis"], 100.0, "clean")
    path = write_generic_csv(rec, tmp_path / "two.csv")
    assert "pelvis.gyro_z" in path.read_text().splitlines()[0]
    back, _ = read_log(path, rate=None)
    assert back.placements == ["right_ankle", "pelvis"]
    np.testing.assert_allclose(back.acc, rec.acc, rtol=1e-7, atol=1e-7)


def test_units_detected_and_overridden(walk_rec, tmp_path):
    g, deg = 9.80665, np.pi / 180
    scaled = Recording(walk_rec.times, walk_rec.acc / g, walk_rec.gyro / deg, ["right_ankle"])
    path = write_generic_csv(scaled, tmp_path / "g_deg.csv")
    back, report = read_log(path, rate=None)
    assert (report.acc_unit, report.gyro_unit) == ("g", "deg/s")
    np.testing.assert_allclose(back.acc, walk_rec.acc, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(back.gyro, walk_rec.gyro, rtol=1e-6, atol=1e-6)
    forced, report = read_log(path, rate=None, acc_unit="m/s^2", gyro_unit="rad/s")
    assert not report.acc_unit_detected and not report.gyro_unit_detected
    np.testing.assert_allclose(forced.acc, scaled.acc, rtol=1e-7, atol=1e-7)


def test_gyro_unit_of_a_phone_at_rest(tmp_path):
    """At rest the noise floor decides: ~0.3 deg/s bias against ~0.01 rad/s."""
    rng = np.random.default_rng(1)
    t = np.arange(0, 5, 0.01)
    acc = np.tile([0.0, 9.81, 0.0], (len(t), 1)) + rng.normal(0, 0.03, (len(t), 3))
    for unit, bias, noise in (("rad/s", 0.01, 0.005), ("deg/s", 0.3, 0.1)):
        gyro = bias + rng.normal(0, noise, (len(t), 3))
        rec = Recording(t, acc[:, None], gyro[:, None], ["right_ankle"])
        _, report = read_log(write_generic_csv(rec, tmp_path / f"{unit[:3]}.csv"), rate=None)
        assert report.gyro_unit == unit


def test_unsorted_and_duplicate_timestamps(walk_rec, tmp_path):
    path = write_generic_csv(walk_rec, tmp_path / "rec.csv")
    lines = path.read_text().splitlines()
    header, rows = lines[0], lines[1:]
    rng = np.random.default_rng(0)
    swaps = rng.choice(len(rows) - 1, 20, replace=False)
    for i in swaps:
        rows[i], rows[i + 1] = rows[i + 1], rows[i]
    dups = rng.choice(len(rows), 15, replace=False)
    rows = rows + [rows[i] for i in dups]
    path.write_text("\n".join([header] + rows) + "\n")
    back, report = read_log(path, rate=None)
    assert report.duplicates["acc"] == 15 and report.duplicates["gyro"] == 15
    assert report.unsorted["acc"] > 0
    assert np.all(np.diff(back.times) > 0)
    np.testing.assert_allclose(back.times, _shifted(walk_rec), atol=2e-6)
    np.testing.assert_allclose(back.acc, walk_rec.acc, rtol=1e-7, atol=1e-7)


def test_gap_reported_not_hidden(walk_rec, tmp_path):
    keep = (walk_rec.times < 2.0) | (walk_rec.times > 2.6)
    holed = Recording(walk_rec.times[keep], walk_rec.acc[keep], walk_rec.gyro[keep],
                      ["right_ankle"])
    path = write_generic_csv(holed, tmp_path / "holed.csv")
    rec, report = read_log(path, max_gap=0.2)
    assert len(report.gaps) == 1
    gap = report.gaps[0]
    t0 = walk_rec.times[0]
    assert gap.start == pytest.approx(walk_rec.times[walk_rec.times < 2.0][-1] - t0, abs=1e-5)
    assert gap.stop == pytest.approx(walk_rec.times[walk_rec.times > 2.6][0] - t0, abs=1e-5)
    assert np.isfinite(rec.channels()).all()
    with pytest.raises(ValueError, match="gap"):
        read_log(path, max_gap=0.2, on_gap="raise")
    _, report = read_log(path, max_gap=1.0)
    assert report.gaps == []


@pytest.mark.parametrize("row, line, expect", [
    ("0.5,1,2,x3,4,5,6", 4, "acc_z"),
    ("0.5,1,2,3,4,5", 4, "expected 7 values"),
    ("0.5,1,2,nan,4,5,6", 4, "finite"),
])
def test_malformed_row_names_line_and_column(tmp_path, row, line, expect):
    path = tmp_path / "bad.csv"
    path.write_text("time_s,acc_x,acc_y,acc_z,gyro_x,gyro_y,gyro_z\n0.0,0,9.8,0,0,0,0\n"
                    f"0.01,0,9.8,0,0,0,0\n{row}\n")
    with pytest.raises(FormatError, match=expect) as err:
        read_log(path)
    assert err.value.line == line and err.value.path == str(path)


def test_unknown_header_and_missing_gyro(tmp_path):
    path = tmp_path / "what.csv"
    path.write_text("a,b,c\n1,2,3\n")
    with pytest.raises(FormatError, match="unknown sensor log"):
        read_log(path)
    path.write_text("time_s,acc_x,acc_y,acc_z\n0,0,9.8,0\n")
    with pytest.raises(FormatError, match="gyro_x"):
        read_log(path, fmt="generic")


def _phyphox_rows(rec: Recording, sep: str = ",", comma: bool = False) -> tuple[str, str]:
    def fmt(v: float) -> str:
        s = f"{v:.9E}"
        return s.replace(".", ",") if comma else s

    acc = [sep.join(f'"{h}"' for h in ["Time (s)", "Acceleration x (m/s^2)",
           "Acceleration y (m/s^2)", "Acceleration z (m/s^2)", "Absolute acceleration (m/s^2)"])]
    gyr = [sep.join(f'"{h}"' for h in ["Time (s)", "Gyroscope x (rad/s)", "Gyroscope y (rad/s)",
           "Gyroscope z (rad/s)", "Absolute (rad/s)"])]
    for t, a, w in zip(rec.times, rec.acc[:, 0], rec.gyro[:, 0]):
        acc.append(sep.join(fmt(v) for v in [t, *a, np.linalg.norm(a)]))
        gyr.append(sep.join(fmt(v) for v in [t + 0.003, *w, np.linalg.norm(w)]))
    return "\n".join(acc) + "\n", "\n".join(gyr) + "\n"


@pytest.mark.parametrize("sep, comma", [(",", False), ("\t", False), (";", True)])
def test_phyphox_exports(walk_rec, tmp_path, sep, comma):
    acc, gyr = _phyphox_rows(walk_rec, sep, comma)
    (tmp_path / "acc.csv").write_text(acc)
    (tmp_path / "gyr.csv").write_text(gyr)
    assert detect_format(tmp_path / "acc.csv") == "phyphox"
    rec, report = read_log([tmp_path / "acc.csv", tmp_path / "gyr.csv"], rate=None)
    assert report.format == "phyphox" and not report.acc_unit_detected
    np.testing.assert_allclose(rec.acc, walk_rec.acc[1:], rtol=1e-6, atol=1e-6)
    # the gyroscope came 3 ms later: interpolated at the accelerometer's instants
    assert np.corrcoef(rec.gyro[:, 0, 0], walk_rec.gyro[1:, 0, 0])[0, 1] > 0.99


def test_phyphox_combined_table_and_linear_acceleration(walk_rec, tmp_path):
    acc, gyr = _phyphox_rows(walk_rec)
    both = [a + "," + g for a, g in zip(acc.splitlines(), gyr.splitlines())]
    (tmp_path / "both.csv").write_text("\n".join(both) + "\n")
    rec, _ = read_log(tmp_path / "both.csv", rate=None)
    np.testing.assert_allclose(rec.acc, walk_rec.acc[1:], rtol=1e-6, atol=1e-6)
    (tmp_path / "lin.csv").write_text(acc.replace("Acceleration x", "Linear Acceleration x"))
    with pytest.raises(FormatError, match="without gravity"):
        read_log(tmp_path / "lin.csv")


def _sensor_logger(folder: Path, rec: Recording, total: bool, ios: bool) -> None:
    folder.mkdir()
    t0 = 1_700_000_000 * 10**9
    sign = -1.0 if ios else 1.0
    gravity = np.tile([0.0, 9.80665, 0.0], (rec.num_samples, 1))  # any split of the total works

    def write(name: str, times: np.ndarray, xyz: np.ndarray) -> None:
        lines = ["time,seconds_elapsed,z,y,x"]
        for t, (x, y, z) in zip(times, xyz):
            lines.append(f"{t0 + round(t * 1e9)},{t:.9f},{z:.9g},{y:.9g},{x:.9g}")
        (folder / name).write_text("\n".join(lines) + "\n")

    acc = rec.acc[:, 0]
    if total:
        write("TotalAcceleration.csv", rec.times, sign * acc)
    else:
        write("Accelerometer.csv", rec.times, sign * (acc - gravity))
        write("Gravity.csv", rec.times, sign * gravity)
    write("Gyroscope.csv", rec.times + 0.002, rec.gyro[:, 0])
    (folder / "Metadata.csv").write_text(
        "version,device name,recording time,platform\n"
        f"3,test,2024-01-01_00-00-00,{'ios' if ios else 'android'}\n")


@pytest.mark.parametrize("total, ios", [(True, False), (False, False), (False, True)])
def test_sensor_logger_export(walk_rec, tmp_path, total, ios):
    folder = tmp_path / "sl"
    _sensor_logger(folder, walk_rec, total, ios)
    assert detect_format(folder) == "sensorlogger"
    rec, report = read_log(folder, rate=None)
    assert report.format == "sensorlogger"
    np.testing.assert_allclose(rec.acc, walk_rec.acc[1:], rtol=1e-6, atol=1e-5)


def test_sensor_logger_without_gravity_refused(walk_rec, tmp_path):
    folder = tmp_path / "sl"
    _sensor_logger(folder, walk_rec, total=False, ios=False)
    (folder / "Gravity.csv").unlink()
    with pytest.raises(FormatError, match="Gravity.csv"):
        read_log(folder)


@pytest.mark.shared
def test_realworld_shin_pair(shared_dir):
    folder = shared_dir.parent / "realworld-shin"
    rec, report = read_log(folder / "acc_walking_shin.csv")
    assert report.format == "realworld" and len(report.files) == 2
    assert (report.acc_unit, report.gyro_unit) == ("m/s^2", "rad/s")
    assert 45.0 < report.source_rate < 55.0
    assert np.isfinite(rec.channels()).all() and rec.is_uniform()
    assert 600 < rec.times[-1] < 660
    assert report.gaps  # the log has stretches of ~1 s without samples: reported
    rest = still_mask(rec.acc[:, 0], rec.gyro[:, 0], 100.0)
    assert rest.sum() > 100  # over a second standing still
    g = rec.acc[rest, 0].mean(axis=0)
    assert 9.5 < np.linalg.norm(g) < 10.3
    assert g[1] > 0.97 * np.linalg.norm(g)  # +y runs up the shin


@settings(max_examples=25, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.integers(50, 120), st.integers(1, 3), st.integers(0, 2**31 - 1))
def test_generic_round_trip_property(tmp_path, n, sensors, seed):
    rng = np.random.default_rng(seed)  # >= 50 samples 20-50 ms apart: more than MIN_DURATION
    times = np.cumsum(rng.uniform(0.02, 0.05, n)) + rng.uniform(0, 1e3)
    acc = rng.normal(0, 50, (n, sensors, 3))
    gyro = rng.normal(0, 10, (n, sensors, 3))
    names = ["right_ankle", "pelvis", "head"][:sensors]
    rec = Recording(times, acc, gyro, names)
    path = write_generic_csv(rec, tmp_path / f"p{seed}.csv", overwrite=True)
    back, _ = read_log(path, rate=None, acc_unit="m/s^2", gyro_unit="rad/s",
                       max_gap=np.inf)
    assert back.placements == (names if sensors > 1 else ["right_ankle"])
    np.testing.assert_allclose(back.times, times - times[0], atol=2e-6)
    np.testing.assert_allclose(back.acc, acc, rtol=1e-7, atol=1e-6)
    np.testing.assert_allclose(back.gyro, gyro, rtol=1e-7, atol=1e-6)


# --- limits and plausibility ranges (issue 18): every bad log is a FormatError naming it ------

@pytest.fixture()
def rows(walk_rec, tmp_path) -> list[str]:
    """The lines of the sample walk as a generic CSV (header first)."""
    return write_generic_csv(walk_rec, tmp_path / "walk.csv").read_text().splitlines()


def _write(tmp_path: Path, lines: list[str], name: str = "bad.csv") -> Path:
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n")
    return path


def _set_cell(lines: list[str], row: int, col: int, value: str) -> list[str]:
    cells = lines[row].split(",")
    cells[col] = value
    return lines[:row] + [",".join(cells)] + lines[row + 1:]


@pytest.mark.parametrize("value, match", [
    ("1e308", "magnitude"), ("nan", "magnitude"), ("-inf", "magnitude"), ("abc", "a number"),
    ("5e4", "not a sensor reading")])
def test_bad_cells_name_the_line(rows, tmp_path, value, match):
    path = _write(tmp_path, _set_cell(rows, 40, 2, value))
    with pytest.raises(FormatError, match=match) as e:
        read_log(path)
    assert e.value.line == 41 and e.value.path == str(path)


def test_a_timestamp_jump_is_refused_not_resampled(rows, tmp_path):
    """A jump of 1e6 s would resample to 1e8 samples per channel: refused at its line."""
    t = float(rows[300].split(",")[0])
    path = _write(tmp_path, rows[:300] + [r.replace(r.split(",")[0], f"{float(r.split(',')[0]) + 1e6:.6f}", 1)
                                          for r in rows[300:]])
    with pytest.raises(FormatError, match="jumps by 1e\\+06 s") as e:
        read_log(path)
    assert e.value.line == 301 and t > 0


def test_rows_a_nanosecond_apart_are_refused(rows, tmp_path):
    lines = [rows[0]] + [f"{k * 1e-9:.9e}," + r.split(",", 1)[1] for k, r in enumerate(rows[1:])]
    with pytest.raises(FormatError, match="no sampling rate"):
        read_log(_write(tmp_path, lines))


@pytest.mark.parametrize("n", [1, 2, 40])
def test_too_short_recordings_are_refused(rows, tmp_path, n):
    with pytest.raises(FormatError, match="at least"):
        read_log(_write(tmp_path, rows[:n + 1]))


def test_milliseconds_in_a_seconds_column_are_detected(walk_rec, rows, tmp_path, caplog):
    lines = [rows[0]] + [f"{float(r.split(',')[0]) * 1e3:.3f}," + r.split(",", 1)[1]
                         for r in rows[1:]]
    with caplog.at_level("WARNING"):
        rec, report = read_log(_write(tmp_path, lines))
    assert report.time_unit == "ms" and "read as ms" in caplog.text
    span = walk_rec.times[-1] - walk_rec.times[0]
    assert abs(report.duration - span) < 0.01 and abs(rec.times[-1] - span) < 0.02


def test_a_slow_log_in_seconds_is_refused_for_its_rate(rows, tmp_path):
    """2 Hz in seconds for 30 s: refused for its rate, not read as milliseconds (2 kHz for
    0.03 s) and refused for its length."""
    lines = [rows[0]] + [f"{k * 0.5:.6f}," + r.split(",", 1)[1] for k, r in enumerate(rows[1:61])]
    with pytest.raises(FormatError, match=r"rate of 2 Hz: too low for gait, expected at least "
                                          r"5 Hz") as e:
        read_log(_write(tmp_path, lines))
    assert "cover" not in str(e.value)


def test_a_log_too_short_to_tell_its_unit_is_refused_with_both_readings(rows, tmp_path):
    """3 samples at 3 Hz in seconds: 0.67 s, or 3 kHz for 0.67 ms; no unit gives a rate that
    lasts a second. The message gave only the millisecond reading's length (0.000667 s)."""
    lines = [rows[0]] + [f"{k / 3:.6f}," + r.split(",", 1)[1] for k, r in enumerate(rows[1:4])]
    with pytest.raises(FormatError, match=r"rate of 3 Hz \(expected at least 5 Hz\); read as "
                                          r"ms, 3e\+03 Hz for only 0.000667 s \(expected at "
                                          r"least 1 s\)"):
        read_log(_write(tmp_path, lines))


@pytest.mark.parametrize("rate", [5.0, 2000.0, 10_000.0])
def test_a_jittered_log_at_any_rate_is_written_increasing_and_read(sample_db, tmp_path, rate):
    """simulate --rate 10000 --noise phone wrote a log the reader refused (2 ms of jitter
    reordered whole 0.1 ms periods: a median step of 71 us); at 2 kHz it wrote neighbours as one
    microsecond; at 5 Hz the jitter put the median rate below the bound a third of the time."""
    for k, clip in enumerate(sample_db.clips[: 16 if rate < 100 else 2]):
        path = write_generic_csv(simulate(clip, ["right_ankle"], rate, "phone", k),
                                 tmp_path / f"{k}.csv")
        assert np.all(np.diff(np.loadtxt(path, delimiter=",", skiprows=1, usecols=0)) > 0)
        report = read_log(path)[1]
        assert report.source_rate == pytest.approx(rate, rel=0.02)
        assert not any(report.duplicates.values()) and not any(report.unsorted.values())


def test_a_log_at_the_lowest_rate_is_read(sample_db, tmp_path):
    """Logs simulated at exactly MIN_RATE (simulate's lowest --rate) are read: a median step
    of 0.20000000000000018 s (float rounding of the timestamps' differences) is 5 Hz, not
    "a rate of 5 Hz: too low for gait, expected at least 5 Hz" (8 of the 16 sample clips)."""
    from imuloco.sensors.reallog import MIN_RATE

    for k, clip in enumerate(sample_db.clips):
        rec = simulate(clip, ["right_ankle"], MIN_RATE, "clean", 0)
        report = read_log(write_generic_csv(rec, tmp_path / f"{k}.csv"))[1]
        assert report.source_rate == pytest.approx(MIN_RATE)


def test_bytes_that_are_not_text_name_their_line(rows, tmp_path):
    path = tmp_path / "bin.csv"
    path.write_bytes(("\n".join(rows[:10]) + "\n").encode() + b"\xff\xfe\x00garbage\n")
    with pytest.raises(FormatError, match="UTF-8") as e:
        read_log(path)
    assert e.value.line == 11
    path.write_bytes(b"time_s," + b"9" * 100_000 + b"\n")
    with pytest.raises(FormatError, match="line longer"):
        read_log(path)


def test_options_dataclass_and_keywords_agree(rows, tmp_path):
    from imuloco.sensors.reallog import LogOptions

    path = _write(tmp_path, rows)
    a, _ = read_log(path, rate=50.0, sigma_s=0.02)
    b, _ = read_log(path, options=LogOptions(rate=50.0, sigma_s=0.02))
    np.testing.assert_array_equal(a.acc, b.acc)
    with pytest.raises(KeyError, match="on_gap"):
        read_log(path, on_gap="ignore")


@settings(max_examples=40, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.tuples(st.integers(0, 200), st.integers(0, 6),
                          st.sampled_from(["", "x", "1e308", "nan", "1e7", "-1e9", "0,5", '"',
                                           "\x00", "1" * 30, "1e-9", "1e300"])),
                min_size=1, max_size=4))
def test_mutated_tables_fail_cleanly_or_read_finite(walk_rec, tmp_path, edits):
    """Any cell edits of a valid log: either a FormatError naming the file, or a finite,
    uniform recording of plausible length."""
    lines = write_generic_csv(walk_rec, tmp_path / "m.csv", overwrite=True).read_text().splitlines()
    for row, col, value in edits:
        row = 1 + row % (len(lines) - 1)
        cells = lines[row].split(",")
        cells[col % len(cells)] = value
        lines[row] = ",".join(cells)
    path = _write(tmp_path, lines, "m.csv")
    try:
        rec, _ = read_log(path)
    except FormatError as e:
        assert e.path == str(path)
        return
    assert np.isfinite(rec.channels()).all() and rec.is_uniform()
    assert rec.num_samples <= 100 * (walk_rec.times[-1] - walk_rec.times[0]) * 10 + 6001


# --- exports shared as zips; the platform of a Sensor Logger export (issue 19) ----------------

def _zip(folder: Path, target: Path, sub: str = "") -> Path:
    import zipfile

    with zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as z:
        for f in sorted(folder.iterdir()):
            z.write(f, sub + f.name)
    return target


def test_zipped_sensor_logger_export_reads_as_its_folder(walk_rec, tmp_path):
    _sensor_logger(tmp_path / "sl", walk_rec, total=True, ios=True)
    zipped = _zip(tmp_path / "sl", tmp_path / "export.csv.zip", "Walk-2024/")
    assert detect_format(zipped) == "sensorlogger"
    a, _ = read_log(tmp_path / "sl", rate=None)
    b, rb = read_log(zipped, rate=None)
    np.testing.assert_array_equal(a.acc, b.acc)
    assert rb.platform == "ios (Metadata.csv)"
    assert str(zipped / "Walk-2024/TotalAcceleration.csv") in rb.files


def test_a_recording_is_named_by_its_file_or_whole_folder(tmp_path, monkeypatch):
    """``reconstruct`` and ``batch`` name a log by its stem, an export folder in full (it was
    titled ``alice`` by its stem, and ``.`` had no name)."""
    (tmp_path / "alice.day1").mkdir()
    (tmp_path / "bob.log.csv").write_text("")
    assert recording_name(tmp_path / "alice.day1") == "alice.day1"
    assert recording_name(str(tmp_path / "bob.log.csv")) == "bob.log"
    monkeypatch.chdir(tmp_path / "alice.day1")
    assert recording_name(".") == "alice.day1"


def test_zipped_phyphox_export(walk_rec, tmp_path):
    acc, gyr = _phyphox_rows(walk_rec)
    (tmp_path / "ph").mkdir()
    (tmp_path / "ph" / "Accelerometer.csv").write_text(acc)
    (tmp_path / "ph" / "Gyroscope.csv").write_text(gyr)
    (tmp_path / "ph" / "device.csv").write_text("property,value\nmodel,x\n")
    zipped = _zip(tmp_path / "ph", tmp_path / "phyphox.zip")
    assert detect_format(zipped) == "phyphox"
    rec, report = read_log(zipped, rate=None)
    assert report.format == "phyphox"
    np.testing.assert_allclose(rec.acc, walk_rec.acc[1:], rtol=1e-6, atol=1e-6)


def test_a_broken_zip_is_a_format_error(tmp_path):
    path = tmp_path / "broken.zip"
    path.write_bytes(b"PK\x03\x04" + b"\x00" * 50)
    with pytest.raises(FormatError) as e:
        read_log(path)
    assert str(path) in str(e.value) and "\\x00" not in str(e.value)


def test_platform_without_metadata_is_guessed_with_a_warning(walk_rec, tmp_path, caplog):
    _sensor_logger(tmp_path / "ios", walk_rec, total=True, ios=True)
    reference, _ = read_log(tmp_path / "ios", rate=None)
    (tmp_path / "ios" / "Metadata.csv").unlink()
    with caplog.at_level("WARNING"):
        assumed, report = read_log(tmp_path / "ios", rate=None)
    assert "assuming Android" in caplog.text and report.platform.startswith("android")
    np.testing.assert_allclose(assumed.acc, -reference.acc)  # why the warning matters
    given_, report = read_log(tmp_path / "ios", rate=None, platform="ios")
    np.testing.assert_allclose(given_.acc, reference.acc)
    assert report.platform == "ios (given)"
    # the uncalibrated accelerometer is in g on iOS, m/s^2 on Android: enough to tell
    lines = ["time,seconds_elapsed,z,y,x"] + [f"{1_700_000_000 * 10**9 + k * 10**7},{k / 100},"
                                              f"{-v[2] / 9.81},{-v[1] / 9.81},{-v[0] / 9.81}"
                                              for k, v in enumerate(walk_rec.acc[:, 0])]
    (tmp_path / "ios" / "AccelerometerUncalibrated.csv").write_text("\n".join(lines) + "\n")
    caplog.clear()
    with caplog.at_level("WARNING"):
        guessed, report = read_log(tmp_path / "ios", rate=None)
    assert "guessed ios" in caplog.text and report.platform.startswith("ios")
    np.testing.assert_allclose(guessed.acc, reference.acc)


@settings(max_examples=80, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.binary(max_size=300) | st.text(alphabet="0123456789.,;-e\n\t\"#na ", max_size=300))
def test_any_bytes_as_a_table_fail_cleanly_or_read_finite(tmp_path, reads_cleanly, content):
    from imuloco.io.sensorlog import read_generic_csv, read_phyphox

    path = tmp_path / "any.csv"
    header = b"time_s,acc_x,acc_y,acc_z,gyro_x,gyro_y,gyro_z\n"
    body = content if isinstance(content, bytes) else content.encode()
    for data, reader in ((header + body, read_generic_csv), (body, read_phyphox)):
        path.write_bytes(data)
        reads_cleanly(reader, path)
    try:
        detect_format(path)
    except FormatError as e:
        assert e.path == str(path)


def test_zip_of_an_unknown_version_is_a_format_error(walk_rec, tmp_path):
    _sensor_logger(tmp_path / "sl", walk_rec, total=True, ios=False)
    blob = bytearray(_zip(tmp_path / "sl", tmp_path / "export.zip").read_bytes())
    at = blob.find(b"PK\x01\x02")
    blob[at + 6] = 166  # "version needed to extract": 16.6, which zipfile refuses
    (tmp_path / "export.zip").write_bytes(bytes(blob))
    with pytest.raises(FormatError, match="export.zip"):
        read_log(tmp_path / "export.zip")


def _table_both_ways(path: Path, monkeypatch, allow_empty: bool = False):
    """What _read_table gives (or the FormatError it raises) with its block fast path and with
    the line-by-line reading alone, in blocks of 64 bytes so that tables span many blocks."""
    from imuloco.io import sensorlog

    monkeypatch.setattr(sensorlog, "BLOCK_BYTES", 64)
    out = []
    for fast in (sensorlog._fast_block, lambda *args: False):
        monkeypatch.setattr(sensorlog, "_fast_block", fast)
        try:
            header, table, lines = sensorlog._read_table(path, allow_empty)
            # NaN (an empty cell where allowed) as None: nan != nan would fail equal tables
            out.append((header, [[None if math.isnan(v) else v for v in row] for row in table.tolist()],
                        lines.tolist()))
        except FormatError as e:
            out.append(str(e))
    return out


LINE = st.one_of(
    st.tuples(*[st.floats(-1e4, 1e4, allow_nan=False)] * 3).map(
        lambda v: ",".join(f"{x:.6g}" for x in v)),  # a good row, most of the time
    st.sampled_from(["", "# a comment", "1,2", "1,2,3,4", "1,nan,3", "1,1e308,2", "1, 2 ,3",
                     '"1",2,3', "1,,3", "1e3,2,3\r", "x,2,3", "1_0,2,3", "   ", "1;2;3"]))


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(LINE, min_size=1, max_size=40), st.booleans(), st.booleans())
def test_block_fast_path_reads_as_the_line_reading(tmp_path, monkeypatch, lines, allow_empty,
                                                  crlf):
    path = tmp_path / "t.csv"
    end = "\r\n" if crlf else "\n"
    path.write_bytes(("a,b,c" + end + end.join(lines) + end).encode())
    fast, slow = _table_both_ways(path, monkeypatch, allow_empty)
    assert fast == slow


def test_a_long_log_reads_fast_and_names_a_late_bad_cell(walk_rec, tmp_path, monkeypatch):
    """Many blocks of the default size, all read by the fast path: the values of the file; a
    bad cell on the last line is named by its line and column."""
    from imuloco.io import sensorlog

    rows = 250_000
    t = np.arange(rows) / 100.0
    data = np.column_stack([t, np.sin(t[:, None] * np.arange(1, 7))])
    path = tmp_path / "long.csv"
    with open(path, "w") as f:
        f.write("time_s,acc_x,acc_y,acc_z,gyro_x,gyro_y,gyro_z\n")
        np.savetxt(f, data, delimiter=",", fmt="%.9g")
    line_reads = []
    slow = sensorlog._parse_lines
    monkeypatch.setattr(sensorlog, "_parse_lines", lambda *a: line_reads.append(1) or slow(*a))
    _, table, lines = sensorlog._read_table(path)
    assert table.shape == (rows, 7) and lines[0] == 2 and lines[-1] == rows + 1
    np.testing.assert_allclose(table, data, rtol=1e-8, atol=1e-9)
    assert not line_reads and path.stat().st_size > 4 * sensorlog.BLOCK_BYTES
    text = path.read_text().split("\n")
    cells = text[-2].split(",")
    text[-2] = ",".join([cells[0], "oops", *cells[2:]])
    path.write_text("\n".join(text))
    with pytest.raises(FormatError, match="column 'acc_x': expected a number, got 'oops'") as e:
        sensorlog._read_table(path)
    assert e.value.line == rows + 1 and line_reads == [1]


def _write_realworld(rec: Recording, folder: Path, acc_name: str, gyro_name: str) -> None:
    t = np.round(1.4e12 + 1000 * rec.times).astype(np.int64)  # Unix ms
    for name, v in ((acc_name, rec.acc[:, 0]), (gyro_name, rec.gyro[:, 0])):
        rows = [f"{i + 1},{t[i]},{x:.7g},{y:.7g},{z:.7g}" for i, (x, y, z) in enumerate(v)]
        (folder / name).write_text("\n".join(["id,attr_time,attr_x,attr_y,attr_z", *rows]) + "\n")


def test_realworld_pair_in_either_order(walk_rec, tmp_path):
    """A RealWorld pair given gyroscope first is read the right way round (it was read with
    the signals' roles swapped: the gyroscope taken for an accelerometer in g, without a
    word); a file without its partner names the one to give."""
    _write_realworld(walk_rec, tmp_path, "acc_walk.csv", "Gyroscope_walk.csv")
    acc, gyro = tmp_path / "acc_walk.csv", tmp_path / "Gyroscope_walk.csv"
    ref, report = read_log(acc, rate=None)
    assert report.acc_unit == "m/s^2"
    np.testing.assert_allclose(ref.acc, walk_rec.acc, rtol=1e-5, atol=1e-5)
    with pytest.raises(FormatError, match="give the acc_ file .* \\(acc_walk.csv\\)"):
        read_log(gyro)
    for files in ((gyro, acc), (acc, gyro)):
        rec, report = read_log(files, rate=None)
        assert (report.acc_unit, report.gyro_unit) == ("m/s^2", "rad/s")
        np.testing.assert_array_equal(rec.acc, ref.acc)
        np.testing.assert_array_equal(rec.gyro, ref.gyro)
    gyro.unlink()
    with pytest.raises(FormatError, match="no gyroscope_walk.csv or gyr_walk.csv beside it"):
        read_log(acc)


def test_a_second_file_with_a_one_file_log_is_refused(walk_rec, tmp_path):
    """Two generic logs given as a pair read the first and dropped the second, without a
    word (``reconstruct a.csv b.csv`` for two walkers); three files read two."""
    a = write_generic_csv(walk_rec, tmp_path / "a.csv")
    b = write_generic_csv(walk_rec, tmp_path / "b.csv")
    with pytest.raises(FormatError, match="b.csv: a second file, but a generic log holds both"):
        read_log((a, b))
    with pytest.raises(ValueError, match="got 3 files"):  # the third was dropped
        read_log((a, b, a))


def test_a_zip_bomb_member_is_refused_unread(tmp_path):
    """A few hundred bytes of bzip2 that unzip to MiBs of line breaks were looked through line
    by line (64 MiB: 105 s); a member unzipping to over 100 times its size is refused, named."""
    import zipfile

    bomb = tmp_path / "bomb.zip"
    with zipfile.ZipFile(bomb, "w", zipfile.ZIP_BZIP2) as z:
        z.writestr("export/Raw Data.csv", b"\n" * (4 << 20))
    assert bomb.stat().st_size < 1000
    with pytest.raises(FormatError, match=r"bomb\.zip/export/Raw Data\.csv: .* more than 100 "
                                          r"times as many"):
        read_log(bomb)


def test_header_sniffing_skips_a_bounded_number_of_blank_lines(walk_rec, tmp_path,
                                                               monkeypatch):
    from imuloco.io import sensorlog

    path = write_generic_csv(walk_rec, tmp_path / "walk.csv")
    text = path.read_text()
    samples = read_log(path)[0].num_samples
    monkeypatch.setattr(sensorlog, "MAX_PREAMBLE_LINES", 5)
    path.write_text("\n" * 5 + text)
    assert read_log(path)[0].num_samples == samples
    path.write_text("\n" * 6 + text)
    with pytest.raises(FormatError, match=r"walk\.csv:6: no header in the first 5 lines"):
        read_log(path)


def test_blank_lines_between_rows_are_read_without_the_line_loop(walk_rec, tmp_path,
                                                                 monkeypatch):
    """Runs of line breaks in a table (a zip bomb's GiB of them) take the fast reading, with
    each row's own line number."""
    from imuloco.io import sensorlog

    path = write_generic_csv(walk_rec, tmp_path / "walk.csv")
    lines = path.read_text().splitlines()
    path.write_text("\n".join([lines[0], "", *lines[1:3], "\r", "", *lines[3:]]) + "\n\n\n")

    def line_loop(*args):
        raise AssertionError("read line by line")

    monkeypatch.setattr(sensorlog, "_parse_lines", line_loop)
    _, table, rows = sensorlog._read_table(path)
    assert len(table) == len(lines) - 1
    assert list(rows[:4]) == [3, 4, 7, 8] and rows[-1] == len(lines) + 3
    np.testing.assert_array_equal(table[0], [float(x) for x in lines[1].split(",")])


def test_a_csv_with_its_own_column_names_reads_through_a_mapping(walk_rec, tmp_path):
    """``--columns time=timestamp,acc_x=ax,...``: another app's CSV (milliseconds, extra
    columns, other names) reads as the generic log it holds; a bad mapping names the fault."""
    from imuloco.errors import UnknownNameError
    from imuloco.io.sensorlog import parse_columns

    t = walk_rec.times * 1000.0  # milliseconds, detected as for any log
    body = np.column_stack([t, walk_rec.acc[:, 0], walk_rec.gyro[:, 0], np.zeros(len(t))])
    path = tmp_path / "other.csv"
    np.savetxt(path, body, delimiter=",", header="timestamp,ax,ay,az,gx,gy,gz,mag",
               comments="", fmt="%.6f")
    with pytest.raises(FormatError, match="--columns"):
        read_log(path)
    columns = parse_columns("time=timestamp, acc_x=ax,acc_y=ay,acc_z=az,gyro_x=gx,gyro_y=gy,"
                            "gyro_z=gz")
    rec, report = read_log(path, rate=None, columns=columns)
    reference, _ = read_log(write_generic_csv(walk_rec, tmp_path / "walk.csv"), rate=None)
    assert report.format == "generic" and report.time_unit == "ms"
    np.testing.assert_allclose(rec.acc, reference.acc, atol=1e-5)
    np.testing.assert_allclose(rec.gyro, reference.gyro, atol=1e-5)
    with pytest.raises(FormatError, match=r"missing column\(s\) \['acc_y'"):
        read_log(path, columns=parse_columns("time=timestamp,acc_x=ax"))
    for bad in ("time", "gyro_q=gz", "time=a,time=b"):
        with pytest.raises(UnknownNameError, match="NAME=COLUMN"):
            parse_columns(bad)


def test_many_gaps_are_one_warning_with_their_count(walk_rec, tmp_path, caplog):
    keep = np.ones(walk_rec.num_samples, bool)
    for start in (100, 300, 500):  # three 0.5 s holes
        keep[start:start + 50] = False
    holes = Recording(walk_rec.times[keep], walk_rec.acc[keep], walk_rec.gyro[keep],
                      walk_rec.placements)
    path = write_generic_csv(holes, tmp_path / "holes.csv")
    with caplog.at_level("WARNING"):
        _, report = read_log(path)
    assert len(report.gaps) == 3
    lines = [r.getMessage() for r in caplog.records if "gap" in r.getMessage()]
    assert len(lines) == 1 and "3 gaps without samples" in lines[0]
    assert lines[0].count(str(path)) == 1


def test_two_phyphox_zips_read_as_accelerometer_and_gyroscope(walk_rec, tmp_path):
    """The built-in "Acceleration with g" and "Gyroscope" experiments export a zip each; two
    passed together read as the pair (they were refused as 'not UTF-8 text')."""
    acc, gyr = _phyphox_rows(walk_rec)
    for name, table in (("acc", acc), ("gyr", gyr)):
        (tmp_path / name).mkdir()
        (tmp_path / name / "Raw Data.csv").write_text(table)
    pair = [_zip(tmp_path / "acc", tmp_path / "acc.zip"), _zip(tmp_path / "gyr",
                                                               tmp_path / "gyr.zip")]
    rec, report = read_log(pair, rate=None)
    assert report.format == "phyphox"
    (tmp_path / "both").mkdir()
    (tmp_path / "both" / "Accelerometer.csv").write_text(acc)
    (tmp_path / "both" / "Gyroscope.csv").write_text(gyr)
    both, _ = read_log(_zip(tmp_path / "both", tmp_path / "both.zip"), rate=None)
    np.testing.assert_array_equal(rec.acc, both.acc)
    np.testing.assert_array_equal(rec.gyro, both.gyro)


def test_a_phyphox_simple_experiment_names_axes_only(walk_rec, tmp_path):
    """phyphox's "Add simple experiment" writes one table per sensor whose columns name an
    axis and a unit ("X (m/s^2)"): the file and the unit say the quantity; a magnetometer's
    table is left alone; a linear accelerometer's alone is refused as without gravity."""
    acc, gyr = _phyphox_rows(walk_rec)

    def axes_only(table: str) -> str:
        head, body = table.split("\n", 1)
        for long in ("Acceleration ", "Gyroscope "):
            head = head.replace(f'"{long}x', '"X').replace(f'"{long}y', '"Y') \
                .replace(f'"{long}z', '"Z')
        return head + "\n" + body

    simple, named = tmp_path / "simple", tmp_path / "named"
    for folder, a, g in ((simple, axes_only(acc), axes_only(gyr)), (named, acc, gyr)):
        (folder / "meta").mkdir(parents=True)
        (folder / "meta" / "device.csv").write_text("property,value\nmodel,x\n")
        (folder / "Accelerometer.csv").write_text(a)
        (folder / "Gyroscope.csv").write_text(g)
    assert '"X (m/s^2)"' in (simple / "Accelerometer.csv").read_text()
    (simple / "Magnetometer.csv").write_text('"Time (s)","X (µT)","Y (µT)","Z (µT)"\n0,1,2,3\n')
    rec, report = read_log(_zip(simple, tmp_path / "simple.zip"), rate=None)
    reference, _ = read_log(_zip(named, tmp_path / "named.zip"), rate=None)
    assert report.format == "phyphox"
    np.testing.assert_array_equal(rec.acc, reference.acc)
    np.testing.assert_array_equal(rec.gyro, reference.gyro)
    linear = tmp_path / "linear"
    linear.mkdir()
    (linear / "linearAccelerometer.csv").write_text(axes_only(acc))
    (linear / "Gyroscope.csv").write_text(axes_only(gyr))
    with pytest.raises(FormatError, match="without gravity"):
        read_log(_zip(linear, tmp_path / "linear.zip"))
