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
