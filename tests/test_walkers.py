"""The walkers file of ``imuloco batch --walkers``: heights by output name, the study's own
columns, and errors that name the file, line and field."""

from __future__ import annotations

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


@pytest.mark.parametrize("text, line, match", [
    ("name,height_m\nalice,1.6\nbbo,1.7\n", 3, r"name 'bbo' matches no recording.*'bob'"),
    ("name,height_m\nacc_walkingshin,1.7\n", 2, r"close: 'acc_walking_shin'"),
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
