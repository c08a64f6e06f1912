"""Xsens text exports (MT Manager, the DOT app, ipol-gait's files) read as sensor logs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings

from imuloco.errors import FormatError
from imuloco.io.logformats import detect_format
from imuloco.io.xsens import read_xsens, unwrap_counter
from imuloco.lab.mutations import mutations
from imuloco.sensors.reallog import read_log

N = 300  # packets at 100 Hz: 3 s
DROPPED = 150  # a packet the wireless link lost
KEPT = np.array([k for k in range(N) if k != DROPPED])
MT_PREAMBLE = ("// Start Time: Unknown\n// Update Rate: 100.0Hz\n// Filter Profile: human (46.1)\n"
               "// Option Flags: AHS Disabled ICC Disabled\n// Firmware Version: 4.0.2\n")


def _signals(k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A foot-like recording: gravity plus a swing (m/s^2), a few rad/s of rotation."""
    t = k / 100.0
    acc = np.stack([2 * np.sin(6 * t), 9.81 + np.cos(5 * t), 0.5 * np.sin(3 * t)], axis=1)
    gyr = np.stack([4 * np.sin(7 * t), 0.3 * np.cos(2 * t), np.sin(5 * t)], axis=1)
    return acc, gyr


def _mt_manager(stf: bool = True, sep: str = "\t", preamble: str = MT_PREAMBLE) -> str:
    """An MT Manager export: PacketCounter wraps at 65,536 after 136 packets, SampleTimeFine
    (10 kHz ticks) at 2^32 after 100, packet 150 dropped, UTC cells empty."""
    acc, gyr = _signals(KEPT)
    names = ["PacketCounter", "SampleTimeFine", "UTC_Nano", "UTC_Year", "Acc_X", "Acc_Y",
             "Acc_Z", "Gyr_X", "Gyr_Y", "Gyr_Z", "Mag_X", "Mag_Y", "Mag_Z"]
    rows = [sep.join(names)]
    for k, a, g in zip(KEPT, acc, gyr):
        fine = (2**32 - 10_000 + 100 * int(k)) % 2**32 if stf else ""
        rows.append(sep.join([f"{(65_400 + k) % 65_536:05d}", str(fine), "", "",
                              *(f"{v:.6f}" for v in (*a, *g)), "-0.6", "0.02", "-0.35"]))
    return preamble + "\n".join(rows) + "\n"


def _dot(sep: str = ",") -> str:
    """A DOT app CSV: SampleTimeFine in 1 MHz ticks (wrapping at 2^32), Gyr in deg/s."""
    acc, gyr = _signals(KEPT)
    rows = ["sep=,", "DeviceTag:,shoe", "FirmwareVersion:,2.0.0", "AppVersion:,2021.0",
            "StartTime: ,2021-08-20_20:21:13_829 GMT+8", "", sep.join(
                ["PacketCounter", "SampleTimeFine", "Euler_X", "Euler_Y", "Euler_Z", "Acc_X",
                 "Acc_Y", "Acc_Z", "Gyr_X", "Gyr_Y", "Gyr_Z"])]
    for k, a, g in zip(KEPT, acc, np.degrees(gyr)):
        fine = (2**32 - 1_000_000 + 10_000 * int(k)) % 2**32
        rows.append(sep.join([str(k), str(fine), "179.9", "-0.25", "-136.2",
                              *(f"{v:.6f}" for v in (*a, *g))]))
    return "\n".join(rows) + "\n"


def _ipol() -> str:
    """ipol-gait's layout: the rate line, then PacketCounter (as floats) and the signals."""
    acc, gyr = _signals(KEPT)
    rows = ["Acquisition frequency: 100 Hz",
            "PacketCounter\tAcc_X\tAcc_Y\tAcc_Z\tGyr_X\tGyr_Y\tGyr_Z\tMag_X\tMag_Y\tMag_Z"]
    rows += ["\t".join([f"{float((65_400 + k) % 65_536)}", *(f"{v:.6f}" for v in (*a, *g)),
                        "-0.6", "0.02", "-0.35"]) for k, a, g in zip(KEPT, acc, gyr)]
    return "\n".join(rows) + "\n"


@pytest.mark.parametrize("name,text,gyro_unit", [
    ("mt.txt", _mt_manager(), "rad/s"),
    ("mt-counter.txt", _mt_manager(stf=False), "rad/s"),  # SampleTimeFine empty: counter/rate
    ("mt.csv", _mt_manager(sep=","), "rad/s"),
    ("mt2022.txt", _mt_manager(preamble="// General information:\n//  MT Manager version: "
                                        "2022.2.0\n// Device settings:\n//  Update Rate: "
                                        "100.0Hz\n"), "rad/s"),
    ("dot.csv", _dot(), "deg/s"),
    ("1-1_rf.txt", _ipol(), "rad/s"),
])
def test_layouts_read_across_wraps_and_a_dropped_packet(tmp_path, name, text, gyro_unit):
    path = tmp_path / name
    path.write_text(text)
    assert detect_format(path) == "xsens"
    rec, report = read_log(path, "right_foot", rate=None)
    assert report.format == "xsens" and rec.placements == ["right_foot"]
    # every packet at its own time, from 0 s, the lost one a 20 ms step
    np.testing.assert_allclose(rec.times, (KEPT - KEPT[0]) / 100.0, atol=1e-9)
    assert np.isclose(np.diff(rec.times)[DROPPED - 1], 0.02) and report.gaps == []
    acc, gyr = _signals(KEPT)
    np.testing.assert_allclose(rec.acc[:, 0], acc, atol=1e-6)
    np.testing.assert_allclose(rec.gyro[:, 0], gyr, atol=1e-6)
    assert (report.acc_unit, report.gyro_unit) == ("m/s^2", gyro_unit)
    assert report.samples == {"acc": N - 1, "gyro": N - 1}


def test_format_named_explicitly_and_at_the_model_rate(tmp_path):
    path = tmp_path / "mt.txt"
    path.write_text(_mt_manager())
    rec, report = read_log(path, "left_foot", "xsens")
    assert report.format == "xsens" and rec.is_uniform() and abs(rec.rate - 100.0) < 1e-6
    with pytest.raises(FormatError, match="one file"):
        read_log(path, fmt="xsens", gyro_path=path)
    with pytest.raises(FormatError, match="one text file per sensor"):
        read_log(tmp_path, fmt="xsens")


def test_a_duplicated_packet_keeps_its_first_copy(tmp_path):
    lines = _mt_manager().splitlines()
    lines.insert(20, lines[19])  # a packet sent twice (ipol-gait has one)
    (tmp_path / "mt.txt").write_text("\n".join(lines) + "\n")
    rec, report = read_log(tmp_path / "mt.txt", rate=None)
    assert report.duplicates == {"acc": 1, "gyro": 1} and len(rec.times) == N - 1


def test_unwrap_counter_16_and_32_bit():
    np.testing.assert_array_equal(unwrap_counter(np.array([65534.0, 65535, 0, 2])),
                                  [65534, 65535, 65536, 65538])
    np.testing.assert_array_equal(unwrap_counter(np.array([2.0**32 - 1, 5]), 2.0**32),
                                  [2.0**32 - 1, 2.0**32 + 5])


def _refused(path: Path, text: str) -> FormatError:
    path.write_text(text)
    with pytest.raises(FormatError) as e:
        read_xsens(path)
    assert e.value.path == str(path)
    return e.value


def test_bad_exports_are_refused_with_file_and_line(tmp_path):
    path = tmp_path / "mt.txt"
    good = _mt_manager()
    head = good.index("PacketCounter")
    e = _refused(path, good.replace("\tGyr_X\tGyr_Y\tGyr_Z", "\tGx\tGy\tGz", 1))
    assert e.line == 6 and "['Gyr_X', 'Gyr_Y', 'Gyr_Z']" in e.message and "'Gx'" in e.message
    e = _refused(path, good[:head] + good[head:].replace("\tAcc_", "\tFreeAcc_", 3))
    assert "without gravity" in e.message
    bad = good.splitlines()
    bad[9] = bad[9].replace("\t-0.6\t", "\tabc\t")  # any column: Mag_X too
    e = _refused(path, "\n".join(bad) + "\n")
    assert (e.line, "'Mag_X'" in e.message, "'abc'" in e.message) == (10, True, True)
    bad = good.splitlines()
    cells = bad[12].split("\t")
    cells[7] = ""  # Gyr_X empty
    bad[12] = "\t".join(cells)
    e = _refused(path, "\n".join(bad) + "\n")
    assert e.line == 13 and "'Gyr_X' is empty" in e.message
    # no SampleTimeFine and no rate: no time
    e = _refused(path, _mt_manager(stf=False).replace("// Update Rate: 100.0Hz\n", ""))
    assert e.line == 5 and "no sample times" in e.message
    assert "no rate stated" in e.message and "SampleTimeFine empty on line 6" in e.message
    # a restarted recording: the counter goes back
    bad = _mt_manager(stf=False).splitlines()
    bad[40:40] = [bad[10]]
    e = _refused(path, "\n".join(bad) + "\n")
    assert e.line == 41 and "goes back" in e.message
    e = _refused(path, _mt_manager(stf=False).replace("\n65401\t", "\n654.5\t"))
    assert e.line == 8 and "PacketCounter: expected a whole number" in e.message


def test_a_stated_rate_beyond_a_float_is_refused_with_the_header_line(tmp_path):
    """A rate line of 400 digits is inf Hz: choosing SampleTimeFine's tick took log(0) and
    raised "ValueError: math domain error" (found by ``imuloco bench --fuzz --readers xsens``)."""
    huge = "// Update Rate: 1" + "0" * 400 + "Hz\n"
    for stf in (True, False):
        e = _refused(tmp_path / "mt.txt", _mt_manager(stf).replace("// Update Rate: 100.0Hz\n",
                                                                   huge))
        assert e.line == 6 and "rate stated above the header is no finite number" in e.message


@pytest.mark.parametrize("text", ["", "\n\n", "// Update Rate: 100.0Hz\n" * 500,
                                  "x" * 100_000 + "\n", "\xff\xfe\x00"])
def test_empty_endless_or_binary_files_are_refused_quickly(tmp_path, text):
    path = tmp_path / "mt.txt"
    path.write_bytes(text.encode("latin-1"))
    with pytest.raises(FormatError) as e:
        read_xsens(path)
    assert e.value.path == str(path)
    with pytest.raises(FormatError):
        detect_format(path)


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(mutations("// Update Rate: 100.0Hz\nPacketCounter\tSampleTimeFine\tAcc_X\tAcc_Y\t"
                      "Acc_Z\tGyr_X\tGyr_Y\tGyr_Z\n" + "".join(
                          f"{65530 + k}\t\t0.1\t9.8\t0.2\t{k % 5}\t0.1\t-0.3\n" for k in range(6))))
def test_mutated_exports_fail_cleanly_or_read_finite(tmp_path, reads_cleanly, data):
    path = tmp_path / "mt.txt"
    path.write_bytes(data)
    reads_cleanly(read_xsens, path)


@pytest.mark.shared
def test_ipol_gait_file_reads_as_realimu_reads_it(real_dir):
    """read_log(fmt="xsens") gives ipol-gait's right-foot samples as imuloco.io.realimu does:
    the same packets at the same times, the same values."""
    from imuloco.io.realimu import _read_ipol_txt, read_ipol

    folder = real_dir / "ipol-gait"
    rec, report = read_log(folder / "1-1_rf.txt", "right_foot", fmt="xsens", rate=None)
    rate, counter, data = _read_ipol_txt(folder / "1-1_rf.txt")
    np.testing.assert_allclose(rec.times, (counter - counter[0]) / rate, atol=1e-9)
    np.testing.assert_array_equal(rec.acc[:, 0], data[:, :3])
    np.testing.assert_array_equal(rec.gyro[:, 0], data[:, 3:])
    assert (report.acc_unit, report.gyro_unit) == ("m/s^2", "rad/s")
    # the trial's recording (three sensors on one grid) holds the same samples at those times
    trial = next(read_ipol(folder / "1-1.json"))
    foot = trial.recording.placements.index("right_foot")
    at = np.searchsorted(trial.recording.times, counter / rate)
    inside = (at < len(trial.recording.times))
    inside[inside] &= np.isclose(trial.recording.times[at[inside]], (counter / rate)[inside])
    assert inside.sum() > 0.9 * len(counter)
    np.testing.assert_allclose(trial.recording.gyro[at[inside], foot], data[inside, 3:],
                               atol=1e-12)
