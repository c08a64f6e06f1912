"""Atomic outputs: a failed write leaves the old file, an input is never a target."""

import pytest

from imuloco.errors import ImulocoError, OutputExistsError
from imuloco.io.atomic import atomic_write, check_output


def test_atomic_write_replaces_only_on_success(tmp_path):
    target = tmp_path / "out.txt"
    target.write_text("old")
    with pytest.raises(RuntimeError), atomic_write(target, "w") as f:
        f.write("half")
        raise RuntimeError("interrupted")
    assert target.read_text() == "old"
    assert list(tmp_path.iterdir()) == [target]  # no temporary file left
    with atomic_write(target, "w") as f:
        f.write("new")
    assert target.read_text() == "new"


def test_check_output_refuses_existing_and_inputs(tmp_path):
    target = tmp_path / "x.csv"
    target.write_text("data")
    with pytest.raises(OutputExistsError, match="--force"):
        check_output(target)
    assert check_output(target, force=True) == target
    with pytest.raises(ImulocoError, match="overwrite an input"):
        check_output(tmp_path / "." / "x.csv", force=True, inputs=[target])


def test_atomic_write_gives_the_permissions_open_would(tmp_path):
    with open(tmp_path / "plain.txt", "w") as f:
        f.write("x")
    with atomic_write(tmp_path / "atomic.txt", "w") as f:
        f.write("x")
    modes = [(tmp_path / n).stat().st_mode & 0o777 for n in ("plain.txt", "atomic.txt")]
    assert modes[0] == modes[1]
