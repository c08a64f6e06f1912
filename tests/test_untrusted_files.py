"""Files that are well formed but wrong, or not the user's (issue 42, items 11, 12, 14, 15, 19):
mixed units per column, two phones in one zip, a rig the BVH writer cannot write back, links
out of an export folder, and a full disk. Each is refused with one clear error, before any work
where it can be, and never quotes more of a file than a short excerpt of one cell."""

from __future__ import annotations

import errno
import zipfile
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from imuloco.cli import cli
from imuloco.data import SAMPLE_DIR
from imuloco.errors import EXCERPT_CHARS, FormatError, ImulocoError
from imuloco.sensors.reallog import read_log

SECRET = "root:x:0:0:root:/root:/bin/bash"


def _walk(n: int = 400, rate: float = 100.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """times (N,), acc (N, 3) m/s^2 with gravity, gyro (N, 3) rad/s of a swinging shank."""
    t = np.arange(n) / rate
    swing = np.sin(2 * np.pi * t)
    acc = np.c_[2.0 * swing, 9.81 + np.cos(2 * np.pi * t), 0.5 * swing]
    gyro = np.c_[0.3 * swing, 0.2 * swing, 4.0 * np.cos(2 * np.pi * t)]
    return t, acc, gyro


def _phyphox(path: Path, units: tuple[str, str, str], quantity: str = "acc") -> Path:
    t, acc, gyro = _walk()
    name, values = ("Acceleration", acc) if quantity == "acc" else ("Gyroscope", gyro)
    head = ['"Time (s)"'] + [f'"{name} {a} ({u})"' for a, u in zip("xyz", units)]
    rows = [",".join(f"{v:.9E}" for v in [ti, *row]) for ti, row in zip(t, values)]
    path.write_text(",".join(head) + "\n" + "\n".join(rows) + "\n", encoding="utf-8")
    return path


# ---- 11: units per column -------------------------------------------------------------------

@pytest.mark.parametrize("quantity, units, odd", [
    ("acc", ("m/s^2", "m/s²", "g"), "Acceleration z (g)"),
    ("gyro", ("rad/s", "deg/s", "rad/s"), "Gyroscope y (deg/s)"),
])
def test_a_phyphox_table_mixing_units_is_refused_naming_the_columns(tmp_path, quantity, units,
                                                                   odd):
    """x, y in m/s^2 and z in g was read as all g (|acc| 98 m/s^2); a deg/s column beside
    rad/s ones as rad/s."""
    acc = _phyphox(tmp_path / "acc.csv", ("m/s^2",) * 3 if quantity == "gyro" else units)
    gyr = _phyphox(tmp_path / "gyr.csv", ("rad/s",) * 3 if quantity == "acc" else units, "gyro")
    with pytest.raises(FormatError) as e:
        read_log([acc, gyr], rate=None)
    msg = str(e.value)
    assert odd in msg and "mix" in msg and ("acc.csv" if quantity == "acc" else "gyr.csv") in msg


def test_one_unit_per_table_still_reads(tmp_path):
    acc = _phyphox(tmp_path / "acc.csv", ("g",) * 3)
    gyr = _phyphox(tmp_path / "gyr.csv", ("rad/s",) * 3, "gyro")
    rec, report = read_log([acc, gyr], rate=None)
    assert report.acc_unit == "g"
    assert np.median(np.linalg.norm(rec.acc[:, 0], axis=1)) > 90  # the file's g, as it says


# ---- 12: one phone per zip ------------------------------------------------------------------

def _sensor_logger_table(t: np.ndarray, xyz: np.ndarray) -> str:
    t0 = 1_700_000_000 * 10**9
    lines = ["time,seconds_elapsed,z,y,x"]
    lines += [f"{t0 + round(ti * 1e9)},{ti:.9f},{z:.9g},{y:.9g},{x:.9g}"
              for ti, (x, y, z) in zip(t, xyz)]
    return "\n".join(lines) + "\n"


def _export_zip(path: Path, members: dict[str, str]) -> Path:
    with zipfile.ZipFile(path, "w") as z:
        for name, text in members.items():
            z.writestr(name, text)
    return path


def test_a_zip_of_two_phones_folders_is_refused_naming_both(tmp_path):
    t, acc, gyro = _walk()
    meta = "version,device name,recording time,platform\n3,x,2024-01-01_00-00-00,android\n"
    two = _export_zip(tmp_path / "two.zip", {
        "a/TotalAcceleration.csv": _sensor_logger_table(t, acc),
        "a/Metadata.csv": meta,
        "b/Gyroscope.csv": _sensor_logger_table(t, gyro)})
    with pytest.raises(FormatError) as e:
        read_log(two, rate=None)
    msg = str(e.value)
    assert "a/TotalAcceleration.csv" in msg and "b/Gyroscope.csv" in msg and "folders" in msg
    # one folder (a phone's export zipped with its folder) reads, and so does phyphox's meta/
    one = _export_zip(tmp_path / "one.zip", {
        "Walk/TotalAcceleration.csv": _sensor_logger_table(t, acc), "Walk/Metadata.csv": meta,
        "Walk/Gyroscope.csv": _sensor_logger_table(t, gyro)})
    assert read_log(one, rate=None)[1].format == "sensorlogger"
    _phyphox(tmp_path / "acc.csv", ("m/s^2",) * 3)
    _phyphox(tmp_path / "gyr.csv", ("rad/s",) * 3, "gyro")
    ph = _export_zip(tmp_path / "ph.zip", {
        "Accelerometer.csv": (tmp_path / "acc.csv").read_text(),
        "Gyroscope.csv": (tmp_path / "gyr.csv").read_text(),
        "meta/device.csv": "property,value\nmodel,x\n", "meta/time.csv": "event,time\n"})
    assert read_log(ph, rate=None)[1].format == "phyphox"


# ---- 15: links out of an export folder, and what errors quote --------------------------------

def test_a_link_out_of_an_export_folder_is_not_followed_nor_quoted(tmp_path):
    t, acc, gyro = _walk()
    secret = tmp_path / "elsewhere" / "passwd"
    secret.parent.mkdir()
    secret.write_text(SECRET + "\n" + SECRET + "\n")
    folder = tmp_path / "export"
    folder.mkdir()
    (folder / "TotalAcceleration.csv").write_text(_sensor_logger_table(t, acc))
    (folder / "Gyroscope.csv").symlink_to(secret)
    with pytest.raises(FormatError) as e:
        read_log(folder, fmt="sensorlogger", rate=None)
    msg = str(e.value)
    assert "Gyroscope.csv" in msg and "link" in msg and "root:x" not in msg
    # a link within the folder is fine (a tidy-up that links a table under another name)
    (folder / "Gyroscope.csv").unlink()
    (folder / "gyro-data.csv").write_text(_sensor_logger_table(t, gyro))
    (folder / "Gyroscope.csv").symlink_to("gyro-data.csv")
    assert read_log(folder, fmt="sensorlogger", rate=None)[1].format == "sensorlogger"


@pytest.mark.parametrize("content", [
    SECRET + "\n" + SECRET + "\n",  # a file of another format: detect_format's error
    "time_s,acc_x,acc_y,acc_z,gyro_x,gyro_y,gyro_z\n0,0,0,0,0,0,0\n" + SECRET * 3 + "\n",
    "time_s,acc_x,acc_y,acc_z,gyro_x,gyro_y,gyro_z\n0,0,0,0,0,0,0\n0," + SECRET + ",0,0,0,0,0\n",
    '"Time (s)","Acceleration x (m/s^2)"\n' + SECRET + "\n",
    "time_s," + SECRET + "\n0,1\n",
])
def test_errors_quote_at_most_a_short_excerpt_of_one_cell(tmp_path, content):
    """Errors name the file and line; of the content they show at most a short, printable
    excerpt of the cell at fault (never a whole line, which may be another file's)."""
    path = tmp_path / "log.csv"
    path.write_text(content)
    with pytest.raises(ImulocoError) as e:
        read_log(path, rate=None)
    msg = str(e.value)
    assert "log.csv" in msg
    assert SECRET[:EXCERPT_CHARS + 1] not in msg and "/bin/bash" not in msg, msg


# ---- 14: a rig the BVH writer cannot write back ----------------------------------------------

def test_a_rig_with_joint_names_bvh_cannot_hold_is_refused_before_the_work(tmp_path,
                                                                         monkeypatch):
    from imuloco.sensors import reallog

    bvh = min(SAMPLE_DIR.glob("*.bvh"))
    rig = tmp_path / "rig.bvh"
    rig.write_text(bvh.read_text().replace("JOINT Shoulder_L\n", "JOINT Shoulder_L{x}\n", 1))
    assert "Shoulder_L{x}" in rig.read_text()
    log = tmp_path / "walk.csv"
    result = CliRunner().invoke(cli, ["simulate", str(bvh), "-o", str(log)])
    assert result.exit_code == 0, result.output

    def no_work(*args, **kwargs):
        raise AssertionError("the recording was reconstructed before the rig was checked")

    monkeypatch.setattr(reallog, "read_log", no_work)
    result = CliRunner().invoke(cli, ["reconstruct", str(log), "-o", str(tmp_path / "o.bvh"),
                                      "--method", "mean", "--skeleton", str(rig)])
    assert result.exit_code == 1 and isinstance(result.exception, SystemExit), result.output
    assert "rig.bvh" in result.output and "Shoulder_L{x}" in result.output
    assert not (tmp_path / "o.bvh").exists()


# ---- 19: a full disk ------------------------------------------------------------------------

def test_a_full_disk_is_one_line_and_leaves_no_file(tmp_path, monkeypatch):
    """Writes failing with ENOSPC (as on a full disk) end in one line naming the file; neither
    the output nor a temporary is left."""
    import os

    from imuloco.io import atomic

    bvh = min(SAMPLE_DIR.glob("*.bvh"))
    real_fsync = os.fsync

    def full(fd):
        real_fsync(fd)
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(atomic.os, "fsync", full)
    out = tmp_path / "walk.csv"
    result = CliRunner().invoke(cli, ["simulate", str(bvh), "-o", str(out)])
    assert result.exit_code == 1 and isinstance(result.exception, SystemExit), result.output
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert lines[-1] == f"Error: no space left on device writing {out}", result.output
    assert "Traceback" not in result.output and "Errno" not in result.output
    assert list(tmp_path.iterdir()) == []
