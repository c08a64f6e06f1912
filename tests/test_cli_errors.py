"""The command line on bad files and arguments: a one-line error naming the file, exit status
1 (an error) or 2 (a usage error), never a traceback; outputs never replace an input."""

from __future__ import annotations

import pytest
from click.testing import CliRunner

from imuloco.cli import cli
from imuloco.data import SAMPLE_DIR

BVH = min(SAMPLE_DIR.glob("*.bvh"))


def run(*args: str) -> tuple[int, str]:
    result = CliRunner().invoke(cli, [str(a) for a in args])
    # a traceback would leave the exception itself here instead of click's SystemExit
    assert result.exception is None or isinstance(result.exception, SystemExit), \
        f"{type(result.exception).__name__}: {result.exception}"
    return result.exit_code, result.output


@pytest.fixture(scope="module")
def log(tmp_path_factory):
    path = tmp_path_factory.mktemp("cli") / "walk.csv"
    code, out = run("simulate", BVH, "-o", path)
    assert code == 0, out
    return path


@pytest.mark.parametrize("command", ["info", "phases"])
def test_motion_commands_on_a_non_bvh(tmp_path, command):
    bad = tmp_path / "notes.bvh"
    bad.write_text("hello\n")
    code, out = run(command, bad)
    assert code == 1 and "notes.bvh:1" in out and "HIERARCHY" in out


def test_reconstruct_to_an_unwritable_place(log):
    code, out = run("reconstruct", log, "-o", "/proc/x.bvh", "--method", "mean")
    assert code == 1 and "/proc/x.bvh" in out and "cannot write" in out


def test_reconstruct_never_replaces_its_input(log):
    before = log.read_bytes()
    code, out = run("reconstruct", log, "-o", log, "--force", "--method", "mean")
    assert code == 1 and "overwrite an input" in out and log.name in out
    assert log.read_bytes() == before


@pytest.mark.parametrize("rate", ["0", "2", "4.9", "10001"])
def test_simulate_rates_the_reader_refuses(tmp_path, rate):
    """simulate writes no log that reconstruct would refuse for its rate (2 Hz was written)."""
    code, out = run("simulate", BVH, "--rate", rate, "-o", tmp_path / "s.csv")
    assert code == 2 and "--rate" in out and not (tmp_path / "s.csv").exists()
    assert "5.0<=x<=10000.0" in out


def test_simulate_rates_follow_the_readers(tmp_path):
    """The bounds are read_log's own constants (imuloco.limits, which the CLI imports without
    numpy)."""
    from imuloco import limits
    from imuloco.sensors import reallog

    assert (reallog.MIN_RATE, reallog.MAX_RATE) == (limits.MIN_RATE, limits.MAX_RATE)
    code, out = run("simulate", BVH, "--rate", "4", "-o", tmp_path / "s.csv")
    assert code == 2 and "5.0<=x<=10000.0" in out
    assert "5.0<=x<=10000.0" in run("simulate", "--help")[1]


def test_train_with_an_invalid_hyperparameter(tmp_path):
    code, out = run("train", "--method", "ridge", "--param", "alpha=-1", "--limit", "3",
                    "-o", tmp_path / "m.npz")
    assert code == 2 and "--param" in out and "alpha" in out
    assert not (tmp_path / "m.npz").exists()


def test_export_onnx_on_a_non_model(log, tmp_path):
    code, out = run("export-onnx", "--model", log, "-o", tmp_path / "x.onnx")
    assert code == 1 and str(log) in out and "pickle" not in out


def test_reconstruct_a_bad_log(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("time_s,acc_x,acc_y,acc_z,gyro_x,gyro_y,gyro_z\n0,1,2,3,4,5,1e308\n")
    code, out = run("reconstruct", bad, "-o", tmp_path / "x.bvh", "--method", "mean")
    assert code == 1 and "bad.csv:2" in out


def test_simulate_never_replaces_its_motion_file(tmp_path):
    import shutil

    motion = tmp_path / "walk.bvh"
    shutil.copy(BVH, motion)
    code, out = run("simulate", motion, "-o", motion, "--force")
    assert code == 1 and "overwrite an input" in out
    assert motion.read_bytes() == BVH.read_bytes()


def test_export_onnx_never_replaces_its_model(tmp_path):
    pytest.importorskip("onnx")
    from imuloco.app.pipeline import shipped_model

    model = tmp_path / "l.npz"
    model.write_bytes(shipped_model("learned", "right_ankle").read_bytes())
    before = model.read_bytes()
    code, out = run("export-onnx", "--model", model, "-o", model, "--force")
    assert code == 1 and "overwrite an input" in out and model.read_bytes() == before


def test_an_interrupted_onnx_export_leaves_the_old_file(tmp_path, monkeypatch):
    onnx = pytest.importorskip("onnx")
    target = tmp_path / "m.onnx"
    target.write_bytes(b"old export")

    def fail(proto):
        raise KeyboardInterrupt  # as if the user stopped the export half-way

    monkeypatch.setattr(onnx.checker, "check_model", fail)
    res = CliRunner().invoke(cli, ["export-onnx", "-o", str(target), "--force"])
    assert res.exit_code == 1 and "Aborted" in res.output
    assert target.read_bytes() == b"old export"
    assert [p.name for p in tmp_path.iterdir()] == ["m.onnx"]  # no temporary file left
    monkeypatch.undo()
    code, out = run("export-onnx", "-o", target, "--force")
    assert code == 0, out
    assert onnx.load(str(target)).graph.input[0].name == "signals"
    assert [p.name for p in tmp_path.iterdir()] == ["m.onnx"]


@pytest.mark.parametrize("placement, module", [("right_foot", "gaitmap"),
                                               ("lower_back", "mobgap")])
@pytest.mark.parametrize("command", ["reconstruct", "batch"])
def test_a_placement_without_the_gait_extra(log, tmp_path, monkeypatch, placement, module,
                                            command):
    """The README's first install (`[viz,deep]`) has neither gaitmap, mobgap nor pandas: a
    shoe or lower-back sensor names the `[gait]` extra before any work (it raised
    ModuleNotFoundError: pandas from the calibration or the gait)."""
    import sys
    for name in ("gaitmap", "mobgap", "pandas"):
        monkeypatch.setitem(sys.modules, name, None)  # as if not installed
    code, out = run(command, log, "--placement", placement, "--method", "mean",
                    *(["-o", tmp_path / "x.bvh"] if command == "reconstruct"
                      else ["--out", tmp_path / "study"]))
    assert code == 1 and module in out and "pip install 'imuloco[gait]'" in out, out
    assert not (tmp_path / "x.bvh").exists() and not (tmp_path / "study").exists()


def test_bench_real_without_the_gait_extra(tmp_path, monkeypatch):
    import sys
    monkeypatch.setitem(sys.modules, "gaitmap", None)
    code, out = run("bench", "--real", tmp_path, "--out", tmp_path / "r")
    assert code == 1 and "pip install 'imuloco[gait]'" in out, out


def test_a_model_of_another_placement_names_the_one_to_give(log, tmp_path, sample_db):
    from imuloco.methods import get_method
    model = get_method("mean").fit(sample_db.subset([0]), ["left_ankle"], "phone", 0)
    code, out = run("reconstruct", log, "--model", model.save(tmp_path / "left.npz"),
                    "-o", tmp_path / "x.bvh")
    assert code == 1 and "not 'right_ankle'" in out and "--placement left_ankle" in out, out


@pytest.mark.parametrize("command, option, value", [
    ("simulate", "--rate", "nan"),  # click's FloatRange let NaN through: arange failed
    ("simulate", "--seed", "-5"),  # numpy's generators take no negative seed
    ("simulate", "--placement", ","),  # no placement: numpy's stack failed
    ("render", "--seconds", "nan"),
    ("render", "--seconds", "-1"),  # an empty video failed in write_video
    ("reconstruct", "--height", "nan"),
    ("reconstruct", "--video-seconds", "0"),
    ("reconstruct", "--piece-seconds", "inf"),
    ("reconstruct", "--piece-seconds", "5"),  # 0 is one piece, else at least 10 s
    ("reconstruct", "--piece-seconds", "-1"),
    ("train", "--limit", "-2"),  # an empty database
    ("train", "--limit", "0"),  # read every clip
    ("train", "--seed", "-1"),
    ("batch", "--jobs", "0"),
    ("bench", "--db-frames", "1e4"),  # int('1e4') failed
    ("bench", "--db-frames", "-5"),
    ("live", "--port", "99999"),  # bind()'s OverflowError
    ("live", "--speed", "0"),  # a replay that never streams
    ("live", "--calibrate-seconds", "nan"),
    ("live", "--calibrate-seconds", "100"),  # the session's own limit, 60 s
])
def test_option_values_out_of_range_are_usage_errors(log, tmp_path, command, option, value):
    """Each value is refused by name when the options are parsed, before any work (each
    crashed with a traceback, or silently did something else)."""
    out = tmp_path / "out"
    rest = {"simulate": [BVH, "-o", out], "render": [BVH, "-o", tmp_path / "x.gif"],
            "reconstruct": [log, "-o", out, "--method", "mean"],
            "train": ["--method", "mean", "-o", out], "batch": [log, "--out", out],
            "bench": ["--method", "mean", "--speed", "--out", out],
            "live": ["--method", "mean"]}[command]
    code, text = run(command, *rest, option, value)
    assert code == 2 and option in text, text
    assert not any(tmp_path.iterdir())


def test_a_video_of_an_unknown_type_is_refused_before_any_work(log, tmp_path):
    code, out = run("reconstruct", log, "-o", tmp_path / "x.bvh", "--video", tmp_path / "x.txt",
                    "--method", "mean")
    assert code == 2 and "--video" in out and ".mp4 or .gif" in out
    assert not any(tmp_path.iterdir())  # the BVH was written before the video failed


def test_a_piece_longer_than_any_recording(log, tmp_path):
    code, out = run("reconstruct", log, "-o", tmp_path / "x.bvh", "--piece-seconds", "1e308",
                    "--method", "mean")
    assert code == 0 and "in 1 piece(s)" in out, out
    code, out = run("reconstruct", log, "-o", tmp_path / "y.bvh", "--piece-seconds", "0",
                    "--method", "mean")  # one piece, as a short recording goes by default
    assert code == 0 and "piece(s)" not in out, out


@pytest.fixture(scope="module")
def one_frame(tmp_path_factory):
    """The bundled clip cut to its first frame: a valid BVH that `info` reads."""
    lines = BVH.read_text().splitlines()
    at = next(i for i, line in enumerate(lines) if line.startswith("Frames:"))
    path = tmp_path_factory.mktemp("one") / "one.bvh"
    path.write_text("\n".join([*lines[:at], "Frames: 1", lines[at + 1], lines[at + 2]]) + "\n")
    return path


@pytest.mark.parametrize("command", ["phases", "evaluate", "simulate"])
def test_a_motion_of_one_frame(one_frame, tmp_path, command):
    args = {"phases": [one_frame], "evaluate": [BVH, one_frame],
            "simulate": [one_frame, "-o", tmp_path / "s.csv"]}[command]
    code, out = run(command, *args)
    assert code == 1 and "one" in out and "at least 2" in out, out
    assert run("info", one_frame)[0] == 0


def test_an_unknown_placement_is_refused_before_reading_data(tmp_path):
    code, out = run("train", "--method", "mean", "--placement", "right_ankle,nowhere",
                    "--data", tmp_path, "-o", tmp_path / "m.npz")
    assert code == 1 and "unknown sensor placement 'nowhere'" in out, out


def test_a_data_folder_without_clips(tmp_path):
    code, out = run("train", "--method", "mean", "--data", tmp_path, "-o", tmp_path / "m.npz")
    assert code == 1 and f"no .bvh files in {tmp_path}" in out


@pytest.mark.parametrize("spec", ["ridge[window=0]", "knn[k=0]", "ridge[alpha=NaN]",
                                  "mousas2017[sigma_scale=1e300]"])  # OverflowError in a fit
def test_bench_refuses_a_method_parameter_out_of_range_before_any_work(tmp_path, spec):
    code, out = run("bench", "--method", spec, "--out", tmp_path / "b")
    name, key = spec.split("[")[0], spec.split("[")[1].split("=")[0]
    assert code == 1 and f"method {name!r}" in out and repr(key) in out, out
    assert "loading" not in out and not (tmp_path / "b").exists()


def test_train_refuses_a_parameter_out_of_range_or_of_the_wrong_kind(tmp_path):
    for param, word in (("window=0", "[1, 1000]"), ("window=2.5", "whole number")):
        code, out = run("train", "--method", "ridge", "--param", param, "-o", tmp_path / "m")
        assert code == 2 and "--param" in out and word in out, out
    assert not any(tmp_path.iterdir())


def test_live_on_a_port_in_use_and_with_a_bad_certificate(log, tmp_path):
    import socket

    pytest.importorskip("websockets")
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        code, out = run("live", "--method", "mean", "--port", port)
    assert code == 1 and f"cannot listen on 127.0.0.1:{port}" in out, out
    code, out = run("live", "--method", "mean", "--cert", log, "--port", "0")
    assert code == 1 and str(log) in out and "PEM certificate" in out, out


@pytest.mark.parametrize("spec, words", [
    ("ridge[alpha=Infinity]", "finite number"),  # JSON's NaN and Infinity pass every bound
    ("mousas2017[shrinkage=NaN]", "finite number"),
    ("tautges2008[periods=3]", "list of finite numbers"),  # tuple(3) failed
    ("tautges2008[periods=[0]]", "items in (0, inf)"),
    ("tautges2008[hop=40]", "hop must be at most window"),  # frames without a pose (NaN)
    ("mousas2017[a_self_phase=0.5]", "must sum to 1"),
    ("pca-local[stride=0]", "'stride' expects value in [1, inf)"),
    ("eom2014[hidden=[0]]", "items in [1, 4096]"),
    ("learned[validation=1]", "'validation' expects value in [0, 1)"),
    ("mean[", "expected NAME[key=value"),  # ran as a method named "mean["
    # upper bounds: each of these ran out of memory, overflowed or ran for ever in a fit
    ("ridge[window=100000]", "'window' expects value in [1, 1000]"),  # 1.1 GiB a clip
    ("knn[window=1000000000]", "'window' expects value in [1, 1000]"),
    ("eom2014[sigma=1e300]", "'sigma' expects value in [0, 1000]"),  # scipy's kernel
    ("eom2014[smooth_iterations=1000000000]", "[0, 10000]"),
    ("eom2014[context=1000000000]", "'context' expects value in [0, 300]"),
    ("mousas2017[sigma_scale=1e300]", "'sigma_scale' expects value in [1e-6, 1e6]"),
    ("learned[threads=1000000000]", "'threads' expects value in [1, 1024]"),  # OpenMP abort
    ("learned[weight_decay=1e300]", "'weight_decay' expects value in [0, 1]"),
    ("learned[lr=1e300]", "'lr' expects value in (0, 1]"),
    ("tautges2008[phases=1000000000]", "'phases' expects value in [1, 360]"),
    ("pca-local[k=1000000000]", "'k' expects value in [1, 1000]"),
])
def test_method_specs_out_of_range_are_refused_by_name(spec, words):
    """Each of these failed deep inside a fit (numpy, scikit-learn, scipy) or gave NaN."""
    from imuloco.errors import ImulocoError
    from imuloco.methods import get_method
    from imuloco.methods.registry import parse_method_spec

    with pytest.raises(ImulocoError) as caught:
        name, params = parse_method_spec(spec)
        get_method(name, **params)
    assert words in str(caught.value)


@pytest.mark.parametrize("spec", [
    "ridge[window=3]", "eom2014[variant=mlp-no-hmm;context=7]", "learned[lag=15]",
    "learned[members=4;epochs=5;strap=0.5;incline=15;threads=2]", "mousas2017[beam=4096]",
    "learned[hidden=8;layers=1;epochs=1;draws=0;window=40;threads=1]", "learned[accel_weight=30]"])
def test_the_variants_of_the_results_stay_within_the_bounds(spec):
    """The upper bounds lie far beyond every value the docs and results use (and the
    defaults: get_method checks them too)."""
    from imuloco.methods import get_method
    from imuloco.methods.registry import available_methods, parse_method_spec

    name, params = parse_method_spec(spec)
    get_method(name, **params)
    for name in available_methods():
        get_method(name)


def test_a_diverged_training_is_an_error_naming_its_rates(sample_db, monkeypatch):
    """Weights gone NaN (a learning rate or weights too large for the data) reached
    scikit-learn's LedoitWolf as a ValueError about missing values."""
    pytest.importorskip("torch")
    from imuloco.errors import InputError
    from imuloco.methods import get_method
    from imuloco.methods.learned import train

    def diverging(net, *args, **kwargs):
        for w in net.parameters():
            w.data.fill_(float("nan"))
        return []

    monkeypatch.setattr(train, "train", diverging)
    method = get_method("learned", hidden=8, layers=1, epochs=1, draws=0, window=40, threads=1)
    with pytest.raises(InputError, match=r"training diverged .* with lr=0.004"):
        method.fit(sample_db.subset([0, 1]))


def test_a_method_built_directly_is_checked_when_fitted(sample_db):
    from imuloco.errors import InputError
    from imuloco.methods.baselines import KnnPose

    with pytest.raises(InputError, match=r"method 'knn': parameter 'k' expects value in \[1"):
        KnnPose(k=0).fit(sample_db.subset([0]))


def test_calibrate_a_corrupted_confidence_file(tmp_path):
    (tmp_path / "confidence-x.npz").write_text("junk\n")
    code, out = run("calibrate", tmp_path)
    assert code == 1 and "confidence-x.npz" in out and "corrupted" in out, out


def test_bench_against_a_revision_git_does_not_know(tmp_path):
    (tmp_path / "clips").mkdir()
    (tmp_path / "clips" / "w.bvh").write_bytes(BVH.read_bytes())
    code, out = run("bench", "--load", tmp_path / "clips", "--against", "no-such-rev",
                    "--out", tmp_path / "r")
    assert code == 1 and "--against no-such-rev" in out, out


def test_ensemble_never_replaces_a_member(tmp_path):
    """`-o` naming a member with --force replaced that member by the ensemble."""
    from imuloco.app.pipeline import shipped_model

    member = tmp_path / "a.npz"
    member.write_bytes(shipped_model("learned", "right_foot").read_bytes())
    before = member.read_bytes()
    code, out = run("ensemble", member, member, "-o", member, "--force")
    assert code == 1 and "overwrite an input" in out and member.read_bytes() == before


def test_a_bad_model_or_rig_leaves_no_partial_demo_and_is_refused_first(tmp_path):
    """``demo`` checks ``--model`` and ``--skeleton`` before writing anything (it wrote
    ``recording.csv`` first), and ``reconstruct`` reads the rig before the log."""
    from imuloco.app.pipeline import demo, reconstruct_file
    from imuloco.errors import ImulocoError

    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a model")
    rig = tmp_path / "rig.csv"
    rig.write_text("time_s,acc_x\n0,1\n")
    for kw in ({"model": bad}, {"skeleton": rig}):
        with pytest.raises(ImulocoError):
            demo(tmp_path / "out", **kw)
        assert not (tmp_path / "out").exists()
    with pytest.raises(ImulocoError, match="rig.csv"):  # the rig's error, not the missing log's
        reconstruct_file(tmp_path / "no-such-log.csv", skeleton=rig)


def test_the_height_range_has_one_source(tmp_path, two_joint_skeleton):
    """--height, a walkers file and height_scale take the body heights of
    :mod:`imuloco.limits` (which the command line imports without numpy); each had its own
    copy of 0.5 to 2.6."""
    from imuloco import limits
    from imuloco.app.walkers import HEIGHT_RANGE_M
    from imuloco.measures import gait

    assert HEIGHT_RANGE_M == (gait.MIN_HEIGHT_M, gait.MAX_HEIGHT_M) == (
        limits.MIN_HEIGHT_M, limits.MAX_HEIGHT_M)
    # options are checked in the order given: a range of its own would pass 2.7 on to the
    # recording, which does not exist
    code, out = run("batch", "--height", "2.7", tmp_path / "none.csv", "--out", tmp_path)
    assert code == 2 and "2.7 is not in the range 0.5<=x<=2.6" in out
    with pytest.raises(ValueError, match=r"\(0.5 to 2.6\), got 2.7"):
        gait.height_scale(two_joint_skeleton, 2.7)


@pytest.mark.parametrize("other", ["--report", "--html", "--video"])
def test_two_outputs_at_one_path_are_refused_before_any_work(log, tmp_path, other):
    """reconstruct -o same.bvh --report same.bvh exited 0 with the JSON in place of the BVH."""
    same = tmp_path / ("same.gif" if other == "--video" else "same.bvh")
    alias = tmp_path / "sub" / ".." / same.name
    (tmp_path / "sub").mkdir()
    code, out = run("reconstruct", log, "-o", same, other, alias, "--method", "mean")
    assert code == 1 and "are one file" in out, out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sub"]


def test_render_and_demo_refuse_two_outputs_at_one_path(tmp_path):
    (tmp_path / "d").mkdir()
    code, out = run("render", BVH, "--out", tmp_path / "d", "-o",
                    tmp_path / "d" / f"{BVH.stem}.html")
    assert code == 1 and "are one file" in out, out
    (tmp_path / "demo").mkdir()
    (tmp_path / "demo" / "demo.gif").symlink_to("demo.mp4")
    code, out = run("demo", "--out", tmp_path / "demo", "--method", "mean", "--force")
    assert code == 1 and "demo.gif is a symbolic link" in out, out
    assert sorted(p.name for p in (tmp_path / "demo").iterdir()) == ["demo.gif"]


def test_force_never_replaces_a_fifo_or_a_link_to_stdout(log, tmp_path):
    import os

    fifo = tmp_path / "out.bvh"
    os.mkfifo(fifo)
    code, out = run("reconstruct", log, "-o", fifo, "--force", "--method", "mean")
    assert code == 1 and "is a FIFO, not a regular file" in out, out
    stdout = tmp_path / "stdout.json"
    stdout.symlink_to("/proc/self/fd/1")
    code, out = run("reconstruct", log, "-o", tmp_path / "a.bvh", "--report", stdout,
                    "--force", "--method", "mean")
    assert code == 1 and "is a symbolic link" in out, out
    assert fifo.is_fifo() and stdout.is_symlink() and not (tmp_path / "a.bvh").exists()


def test_a_report_names_the_bvh_it_belongs_to(log, tmp_path):
    import json

    from imuloco.io.atomic import sha256_file

    code, out = run("reconstruct", log, "-o", tmp_path / "a.bvh", "--report",
                    tmp_path / "a.json", "--method", "mean")
    assert code == 0, out
    report = json.loads((tmp_path / "a.json").read_text())
    assert report["outputs"] == {"bvh": "a.bvh", "bvh_sha256": sha256_file(tmp_path / "a.bvh")}
    # nothing else but the readable summary beside the report (a.md, a-*.png): no temporaries
    assert {p.name for p in tmp_path.iterdir() if not p.name.startswith("a-")} == {
        "a.bvh", "a.json", "a.md"}


def test_reconstruct_refuses_a_fifo_as_its_recording(tmp_path):
    """A FIFO named .csv was read for ever."""
    import os

    fifo = tmp_path / "walk.csv"
    os.mkfifo(fifo)
    code, out = run("reconstruct", fifo, "-o", tmp_path / "a.bvh", "--method", "mean")
    assert code == 1 and "walk.csv: not a regular file" in out, out


def test_calibrate_a_confidence_file_declaring_a_huge_array(tmp_path):
    """An array header declaring shape (1e6, 1e7) made np.load allocate 72.8 TiB: declared
    shapes are checked against the file before anything is allocated."""
    import io
    import zipfile

    import numpy as np

    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, {"descr": "<f8", "fortran_order": False,
                                               "shape": (1_000_000, 10_000_000)})
    with zipfile.ZipFile(tmp_path / "confidence-x.npz", "w") as z:
        z.writestr("actual_m.npy", buf.getvalue() + b"\0" * 64)
    code, out = run("calibrate", tmp_path)
    assert code == 1 and "confidence-x.npz" in out and "'actual_m' declares float64 of shape " \
        "(1000000, 10000000) (80,000,000,000,000 bytes)" in out, out
