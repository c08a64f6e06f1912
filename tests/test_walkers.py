"""The walkers file of ``imuloco batch --walkers``: heights by output name, the study's own
columns, one file for part of the study's recordings, and errors that name the file, line and
field."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from imuloco.app.batch import WALKER_FIELDS
from imuloco.app.walkers import read_walkers
from imuloco.errors import FormatError

NAMES = ["alice", "bob", "acc_walking_shin", "walker1_log"]


def _file(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "walkers.csv"
    path.write_text(text)
    return path


def test_heights_and_the_studys_own_columns(tmp_path):
    path = _file(tmp_path, "\ufeffname,height_m,age,group,score\n"  # a spreadsheet's BOM
                           "alice,1.62,31,control,0.5\n bob ,,,patient,2\n,,,,\n"
                           "acc_walking_shin,1.8,45,,1e3\n")
    w = read_walkers(path, NAMES, WALKER_FIELDS)
    assert w.heights == {"alice": 1.62, "acc_walking_shin": 1.8}  # bob: the default
    assert [(f.name, str(f.type)) for f in w.fields] == [
        ("age", "int64"), ("group", "string"), ("score", "double")]
    assert w.columns("bob") == {"age": None, "group": "patient", "score": 2.0}
    assert w.columns("walker1_log") == {"age": None, "group": None, "score": None}  # no row


def test_one_file_serves_part_of_the_studys_recordings(tmp_path, caplog):
    """Rows of walkers of other batches are counted in one warning (``alicee`` is close to
    ``alice``, who has a row: not a typo); recordings without a row are named in another."""
    rows = "".join(f"p{k:03d},1.{k:02d},{k}\n" for k in range(10, 22))
    path = _file(tmp_path, f"name,height_m,age\nalice,1.62,31\nalicee,1.7,40\n{rows}")
    with caplog.at_level(logging.WARNING, "imuloco.app.walkers"):
        w = read_walkers(path, NAMES, WALKER_FIELDS)
    assert w.heights["alice"] == 1.62 and w.columns("alice") == {"age": 31}
    assert w.columns("bob") == {"age": None}
    assert [r.getMessage() for r in caplog.records] == [
        f"{path}: 13 walkers have no recording in this batch",
        (f"{path}: no row for 3 recording(s) of this batch, which get the default height "
         "(--height, else the model skeleton's): bob, acc_walking_shin, walker1_log")]
    caplog.clear()
    with caplog.at_level(logging.WARNING, "imuloco.app.walkers"):
        read_walkers(_file(tmp_path, "name,height_m\nalice,1.6\nzed,1.7\n"),
                     [*NAMES, "carol", "dave"], WALKER_FIELDS)
    assert [r.getMessage().split(": ", 1)[1] for r in caplog.records] == [
        "1 walker has no recording in this batch",
        ("no row for 5 recording(s) of this batch, which get the default height (--height, "
         "else the model skeleton's): bob, acc_walking_shin, walker1_log, ...")]
    caplog.clear()
    with caplog.at_level(logging.WARNING, "imuloco.app.walkers"):
        read_walkers(_file(tmp_path, "name,height_m\nalice,1.6\nbob,\n"), NAMES[:2])
    assert not caplog.records  # every row a recording, every recording a row


@pytest.mark.parametrize("text, line, match", [
    ("name,height_m\nalice,1.6\nbbo,1.7\n", 3, r"name 'bbo' matches no recording.*'bob'"),
    ("name,height_m\nacc_walkingshin,1.7\n", 2, r"close: 'acc_walking_shin'"),
    ("name,height_m\nzed,1.7\nwalker1_logg,1.6\nalice,1.6\n", 3,
     r"close: 'walker1_log', without a row.*give 'walker1_log' a row too"),
    ("name,height_m\nzed,1.7\nzed,1.8\n", 3, r"'zed' is on lines 2 and 3"),  # not in batch
    ("name,height_m\nzed,170\n", 2, r"'170' is not a body height"),
    ("name,height_m\nalice,1.6\nbob,1.7\nalice,1.65\n", 4, r"'alice' is on lines 2 and 4"),
    ("name,height_m\nalice,175\n", 2, r"'175' is not a body height.*\(metres, not centim"),
    ("name,height_m\nalice,tall\n", 2, r"field 'height_m': 'tall'.*expected 0.5 to 2.6"),
    ("name,height_m\nalice,nan\n", 2, r"expected 0.5 to 2.6"),
    ("name,height_m\n,1.7\n", 2, r"field 'name': empty"),
    ("name,height_m\nalice,1.7,extra\n", 2, r"more cells than the header's 2"),
    ("name,height\nalice,1.7\n", 1, r"columns 'name' and 'height_m'"),
    ("name,height_m,age,age\n", 1, r"\['age'\] appear twice"),
    ("name,height_m,speed_mps\n", 1, r"\['speed_mps'\] are batch's own"),
])
def test_errors_name_the_file_line_and_field(tmp_path, text, line, match):
    path = _file(tmp_path, text)
    with pytest.raises(FormatError, match=match) as e:
        read_walkers(path, NAMES, WALKER_FIELDS)
    assert (e.value.path, e.value.line) == (str(path), line)
