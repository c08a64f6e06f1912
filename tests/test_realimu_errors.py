"""Malformed real-data folders (``read_trials``) end in a FormatError naming the file and what
was expected: each case is one that ``imuloco bench --fuzz N --readers real`` found ending in a
foreign exception, a segmentation fault, a hang or an implausible trial before the fix."""

from __future__ import annotations

import json
import re
import subprocess
import sys

import numpy as np
import pytest

from imuloco.errors import FormatError
from imuloco.io.realimu import GaitDefinition, read_trials
from imuloco.lab import fuzz_real as fr


def _folder(tmp_path, layout: int, **replace: bytes):
    """The fuzz bench's valid seed folder of ``layout`` (0 pyshoe-vicon, 1 ipol-gait,
    2 mobilise-d-lab), with files replaced (``None`` removes one)."""
    files = {**fr.real_seeds()[layout], **replace}
    for name, data in files.items():
        if data is not None:
            (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
            (tmp_path / name).write_bytes(data)
    return tmp_path


def _pyshoe(**changes) -> bytes:
    variables = fr._pyshoe_vars()
    variables.update(changes)
    return fr._savemat(variables)


def _ipol_json(**changes) -> bytes:
    return json.dumps({**fr._ipol_meta(), **changes}).encode()


def _mobilise(path: str, value) -> bytes:
    variables = fr._mobilise_vars()
    fr._set_path(variables, ["data", "TimeMeasure1", "Test5", "Trial1", *path.split(".")], value)
    return fr._savemat(variables)


def _mat_of_wrong_element() -> bytes:
    data = bytearray(fr._savemat({"x": np.array([[1.5]])}))
    data[128] = 1  # the first variable's tag says miINT8 where miMATRIX is expected
    return bytes(data)


COUNTERS = [float(c) for c in range(60)]
CASES = {
    # scipy's reader: TypeError "Expecting miMATRIX type here"
    "mat-element": (0, {fr.PYSHOE: _mat_of_wrong_element()}, "a_LLIO.mat", "MATLAB v5"),
    # ValueError (float of text), a reshape error, a bout from 0 s to 0 s, times going back
    "mat-text": (0, {fr.PYSHOE: _pyshoe(imu_data="walking")}, "a_LLIO.mat", "'imu_data'"),
    "mat-struct": (0, {fr.PYSHOE: _pyshoe(GCP={"a": 1.0})}, "a_LLIO.mat", "'GCP'"),
    "stride-index-huge": (0, {fr.PYSHOE: _pyshoe(strideIndex=np.full((1, 3), 1e300))},
                          "a_LLIO.mat", "strideIndex"),
    "stride-index-one-sample": (0, {fr.PYSHOE: _pyshoe(strideIndex=[[0.2, 0.7]])},
                                "a_LLIO.mat", "different samples"),
    "times-back": (0, {fr.PYSHOE: _pyshoe(timestamps_all=np.arange(200)[None, ::-1] / 200)},
                   "a_LLIO.mat", "increasing"),
    # TypeError ("in" on an int), ValueError (float of "x", a reshape), RecursionError
    "json-number": (1, {"1-1.json": b"3"}, "1-1.json", "top level: expected a struct"),
    "json-text-field": (1, {"1-1.json": _ipol_json(TrialBoundaries="x")}, "1-1.json",
                        "TrialBoundaries"),
    "json-odd-events": (1, {"1-1.json": _ipol_json(RightFootEvents=[1, 2, 3])}, "1-1.json",
                        "RightFootEvents"),
    "json-deep": (1, {"1-1.json": b"[" * 100_000 + b"]" * 100_000}, "1-1.json", "not JSON"),
    "json-reversed": (1, {"1-1.json": _ipol_json(TrialBoundaries=[55, 5])}, "1-1.json",
                      "TrialBoundaries"),
    # json missing: no trial at all, silently
    "json-missing": (1, {"1-1.json": None}, "", "no *.json"),
    # ValueError from np.arange over a NaN counter; a 1e15 jump allocates without end
    "counter-nan": (1, {"1-1_rf.txt": fr._ipol_txt(COUNTERS[:5] + [float("nan")])},
                    "1-1_rf.txt:8", "PacketCounter"),
    "counter-jump": (1, {"1-1_lb.txt": fr._ipol_txt(COUNTERS[:30] + [c + 1e4 for c in
                                                                      COUNTERS[30:]])},
                     "1-1_lb.txt:33", "jumps by 10001"),
    # a rate of 0 Hz gives infinite times, sensors that do not overlap an empty recording
    "rate-zero": (1, {"1-1_lf.txt": fr._ipol_txt(COUNTERS, fr.IPOL_HEADER.replace("100", "0"))},
                  "1-1_lf.txt:1", "1-1000 Hz"),
    "no-overlap": (1, {"1-1_lf.txt": fr._ipol_txt([c + 1000 for c in COUNTERS])}, "1-1.json",
                   "do not overlap"),
    # UserWarning "Empty input file" (an error under pytest); UnicodeDecodeError
    "txt-header-only": (1, {"1-1_lb.txt": fr.IPOL_HEADER.encode()}, "1-1_lb.txt:3",
                        "no samples"),
    "txt-binary": (1, {"1-1_lb.txt": fr._ipol_txt(COUNTERS) + b"\xff\xfe\x00\x91\n"},
                   "1-1_lb.txt", "tab-separated"),
    "txt-nan-cell": (1, {"1-1_rf.txt": fr._ipol_txt(COUNTERS).replace(b"\t9.81\t", b"\tnan\t",
                                                                       1)},
                     "1-1_rf.txt:3", "finite"),
    # AttributeError (.values of text), IndexError (a number indexed by "Acc"), ValueError
    # (Recording's shapes), TypeError (float of a struct), a rate of 1e300 Hz
    "data-text": (2, {fr.MOBILISE: fr._savemat({"data": "walking"})}, "data.mat",
                  "data: expected a struct"),
    "lowerback-number": (2, {fr.MOBILISE: _mobilise("SU.LowerBack", np.inf)}, "data.mat",
                         "SU.LowerBack: expected a struct"),
    "gyr-length": (2, {fr.MOBILISE: _mobilise("SU.LowerBack.Gyr", np.zeros((5, 3)))},
                   "data.mat", "LowerBack.Gyr: expected (300, 3)"),
    "fs-huge": (2, {fr.MOBILISE: _mobilise("SU.LowerBack.Fs", {"Acc": 1e300})}, "data.mat",
                "1-1000 Hz"),
    "microwb-struct": (2, {fr.MOBILISE: _mobilise("Standards.INDIP.MicroWB", np.array(
        [{**{k: 1.0 for k in ("Start", "NumberStrides", "Cadence", "AverageStrideLength",
                              "WalkingSpeed", "InitialContact_Event")}, "End": {"a": 1.0}}],
        dtype=object))}, "data.mat", "MicroWB.End: expected a number"),
    # JSONDecodeError, AttributeError (.get of a list)
    "metadata-json": (2, {fr.MOBILISE_META: b"{"}, "participant_metadata.json", "not JSON"),
    "metadata-list": (2, {fr.MOBILISE_META: b'{"HA": {"001": []}}'},
                      "participant_metadata.json", "HA.001: expected a struct"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_a_malformed_real_folder_is_a_format_error(tmp_path, case):
    layout, replace, where, what = CASES[case]
    folder = _folder(tmp_path, layout, **replace)
    with pytest.raises(FormatError, match=re.escape(what)) as info:
        list(read_trials(folder))
    assert where in str(info.value)


def test_the_seed_folders_read(tmp_path):
    """Each layout's trial, its reference declaring its data set's gait definition."""
    definitions = (GaitDefinition.STRIDES_OVER_TRIAL, GaitDefinition.DISTANCE_OVER_STEPS,
                   GaitDefinition.BOUT_MEANS)
    for layout, definition in enumerate(definitions):
        (trial,) = read_trials(_folder(tmp_path / str(layout), layout))
        assert trial.recording.num_samples > 50
        assert trial.reference.definition is definition


def test_a_file_that_crashes_scipys_reader_is_a_format_error(tmp_path):
    """A data element of type 8 (none) makes scipy 1.17's reader dereference a NULL pointer
    (scipy PR 25349): without the forked probe the process dies of a segmentation fault."""
    data = bytearray(fr._savemat({"x": np.array([[1.5]])}))
    at = data.rfind(bytes.fromhex("0900000008000000"))  # the miDOUBLE tag of the value
    data[at] = 8
    (tmp_path / "a_LLIO.mat").write_bytes(bytes(data))
    code = ("import sys\nfrom imuloco.errors import FormatError\nfrom imuloco.io.realimu import "
            f"read_trials\ntry:\n    list(read_trials({str(tmp_path)!r}))\nexcept FormatError as e:"
            "\n    print(e)\n    sys.exit(3)\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False,
                         timeout=120)
    assert run.returncode == 3, run.stderr[-500:]
    assert "a_LLIO.mat: not a readable MATLAB v5 file" in run.stdout
    assert "signal 11" in run.stdout



def test_a_file_scipys_reader_never_finishes_is_refused_not_waited_for(tmp_path, monkeypatch):
    """The forked probe gives up after its time limit, kills the reader and refuses the file
    (here scipy's reader is replaced by one that never returns)."""
    import time

    import imuloco.io.realimu as ri

    (tmp_path / "a_LLIO.mat").write_bytes(fr._savemat({"x": np.array([[1.5]])}))
    monkeypatch.setattr(ri, "loadmat", lambda *a, **k: time.sleep(3600))
    monkeypatch.setattr(ri, "LOADMAT_TIMEOUT_S", 0.3)
    start = time.monotonic()
    with pytest.raises(FormatError, match=r"a_LLIO.mat: .*still reading it after 0 s"):
        list(read_trials(tmp_path))
    assert time.monotonic() - start < 30
