"""The command line's shared behaviour: one error handler, shared option blocks, consistent
output options (``--out DIR`` for folders, ``-o FILE`` for files), rounded summaries."""

from __future__ import annotations

import json
import re

import pytest
from click.testing import CliRunner

from imuloco.cli import cli
from imuloco.io.bvh import write_bvh
from imuloco.io.logformats import FORMATS
from imuloco.io.sensorlog import write_generic_csv
from imuloco.sensors.simulate import simulate


@pytest.fixture(scope="module")
def model_file(tmp_path_factory, ridge_without_demo_clip):
    return ridge_without_demo_clip.save(tmp_path_factory.mktemp("m") / "ridge.npz")


@pytest.fixture(scope="module")
def walk(sample_db):
    from imuloco.app.pipeline import DEMO_CLIP

    return next(c for c in sample_db.clips if c.name == DEMO_CLIP)


@pytest.fixture(scope="module")
def log_file(tmp_path_factory, walk):
    rec = simulate(walk, ["right_ankle"], 100.0, "phone", seed=2)
    return write_generic_csv(rec, tmp_path_factory.mktemp("log") / "walk.csv")


def _error_lines(output: str) -> list[str]:
    # split on newlines only: a progress bar redraws its line with carriage returns
    return [line for line in output.split("\n") if "Error:" in line]


def test_a_library_error_is_one_line_of_its_own_after_the_progress_bar(tmp_path, model_file,
                                                                        log_file):
    # the log reads (before the bar: it decides the pieces), the model does not fit it
    res = CliRunner().invoke(cli, ["reconstruct", str(log_file), "--model", str(model_file),
                                   "--placement", "left_ankle", "-o", str(tmp_path / "o.bvh")])
    assert res.exit_code == 1
    assert "reconstruct:" in res.output  # the progress bar was drawn ...
    (line,) = _error_lines(res.output)
    assert line.startswith("Error: ") and "ridge.npz" in line  # ... and the error is not on it
    assert "Traceback" not in res.output


def test_a_bad_log_is_one_line_naming_its_line(tmp_path, model_file):
    bad = tmp_path / "bad.csv"
    bad.write_text("time_s,acc_x,acc_y,acc_z,gyro_x,gyro_y,gyro_z\n0,1,2,3,4,5,6\n"
                   "0.01,1,2,x,4,5,6\n")
    res = CliRunner().invoke(cli, ["reconstruct", str(bad), "--model", str(model_file), "-o",
                                   str(tmp_path / "o.bvh")])
    assert res.exit_code == 1
    (line,) = _error_lines(res.output)
    assert line.startswith("Error: ") and "bad.csv:3" in line
    assert "Traceback" not in res.output


@pytest.mark.parametrize(("args", "message"), [
    (["simulate", "{bvh}", "--placement", "left_ear", "-o", "{tmp}/s.csv"],
     "unknown sensor placement 'left_ear'"),
    (["train", "--method", "nosuch", "-o", "{tmp}/m.npz"], "unknown method 'nosuch'"),
    (["bench", "--method", "ridge[window", "--out", "{tmp}/b"], "expected NAME[key=value"),
    (["reconstruct", "{log}", "--method", "nosuch", "-o", "{tmp}/r.bvh"],
     "unknown method 'nosuch'"),
])
def test_user_errors_print_a_plain_message(tmp_path, walk, log_file, args, message):
    bvh = write_bvh(walk.slice(0, 10), tmp_path / "w.bvh")
    args = [a.format(bvh=bvh, tmp=tmp_path, log=log_file) for a in args]
    res = CliRunner().invoke(cli, args)
    assert res.exit_code == 1, res.output
    (line,) = _error_lines(res.output)
    assert line.startswith("Error: ") and message in line
    assert "Error: '" not in line  # no KeyError quotes around the message


@pytest.mark.parametrize(("param", "message"), [
    ("windw=3", "no parameter 'windw'"), ("window", "--param: expected key=value")])
def test_bad_hyperparameters_are_usage_errors(tmp_path, param, message):
    res = CliRunner().invoke(cli, ["train", "--method", "ridge", "--param", param, "-o",
                                   str(tmp_path / "m.npz")])
    assert res.exit_code == 2 and message in res.output and "--param" in res.output
    assert not (tmp_path / "m.npz").exists()


def test_outputs_are_never_replaced_without_force_nor_an_input(tmp_path, log_file, model_file):
    out = tmp_path / "r.bvh"
    out.write_text("mine")
    res = CliRunner().invoke(cli, ["reconstruct", str(log_file), "--model", str(model_file),
                                   "-o", str(out)])
    assert res.exit_code == 1 and f"{out} exists; pass --force" in res.output
    assert out.read_text() == "mine"
    res = CliRunner().invoke(cli, ["reconstruct", str(log_file), "--model", str(model_file),
                                   "-o", str(tmp_path / "x.bvh"), "--report", str(log_file),
                                   "--force"])
    assert res.exit_code == 1 and "would overwrite an input" in res.output
    assert log_file.read_text().startswith("time_s")


def test_reconstruct_summary_rounds_numbers_to_what_they_mean(tmp_path, log_file, model_file):
    res = CliRunner().invoke(cli, ["reconstruct", str(log_file), "--model", str(model_file),
                                   "-o", str(tmp_path / "r.bvh"), "--report",
                                   str(tmp_path / "r.json")])
    assert res.exit_code == 0, res.output
    line = next(ln for ln in res.output.split("\n") if "steps/min" in ln)
    cadences = re.findall(r"cadence (\S+) steps/min .*raw signal: (\S+)\), (\S+) from", line)
    assert cadences and all(re.fullmatch(r"\d+\.\d|–", v) for v in cadences[0]), line
    assert re.search(r"speed (\d+\.\d\d|–) m/s", line), line
    report = json.loads((tmp_path / "r.json").read_text())  # the report keeps its digits
    values = [report["gait"]["cadence_rhythm_spm"], report["signal_cadence_spm"],
              report["gait"]["cadence_spm"]]
    assert any(v is not None for v in values)
    assert list(cadences[0]) == ["–" if v is None else f"{v:.1f}" for v in values]


def test_reconstruct_says_a_lower_back_sensors_gait_and_its_note(tmp_path, sample_db, walk):
    """A lower-back sensor's gait is Mobilise-D's on its own signal, whose stride lengths need
    the walker's height: without --height the command says whose stature it took (it was
    only in the JSON report)."""
    pytest.importorskip("mobgap")
    from imuloco.methods import get_method

    rec = simulate(walk, ["lower_back"], 100.0, "phone", seed=2)
    log = write_generic_csv(rec, tmp_path / "back.csv")
    model = get_method("mean").fit(sample_db.subset([0, 1]), ["lower_back"], "phone", 0)
    args = ["reconstruct", str(log), "--placement", "lower_back", "--model",
            str(model.save(tmp_path / "mean.npz"))]
    for extra, note in (([], True), (["--height", "1.8"], False)):
        res = CliRunner().invoke(cli, [*args, *extra, "-o", str(tmp_path / "b.bvh"), "--force"])
        assert res.exit_code == 0, res.output
        assert "gait: the lower_back sensor's signal: mobgap" in res.output, res.output
        assert ("gait note: no --height given: the skeleton's stature" in res.output) == note


def test_reconstruct_counts_a_shoe_sensors_steps_as_steps(tmp_path, sample_db, walk):
    """One shoe sensor finds its own foot's strikes and counts two steps each: the summary
    said "N detected strikes" of twice the strikes it found."""
    pytest.importorskip("gaitmap")
    from imuloco.methods import get_method

    log = write_generic_csv(simulate(walk, ["right_foot"], 100.0, "phone", seed=2),
                            tmp_path / "shoe.csv")
    model = get_method("mean").fit(sample_db.subset([0, 1]), ["right_foot"], "phone", 0)
    res = CliRunner().invoke(cli, ["reconstruct", str(log), "--placement", "right_foot",
                                   "--model", str(model.save(tmp_path / "mean.npz")),
                                   "-o", str(tmp_path / "s.bvh"), "--report",
                                   str(tmp_path / "s.json")])
    assert res.exit_code == 0, res.output
    report = json.loads((tmp_path / "s.json").read_text())
    steps = int(report["gait"]["steps"])
    assert steps > 4 and len([s for s in report["strides"] if s["foot"] == "right"]) < steps
    assert f"from {steps} steps;" in res.output and "detected strikes" not in res.output


def test_log_format_choices_come_from_sensorlog():
    for command in ("reconstruct", "batch", "live"):
        res = CliRunner().invoke(cli, [command, "--help"])
        assert res.exit_code == 0
        shown = re.search(r"--format \[([^\]]+)\]", res.output.replace("\n", " "))
        assert shown, res.output
        assert [c.strip() for c in shown.group(1).split("|")] == ["auto", *FORMATS]
    res = CliRunner().invoke(cli, ["reconstruct", "x.csv", "--format", "nosuch", "-o", "o.bvh"])
    assert res.exit_code == 2 and "nosuch" in res.output


def test_shared_option_blocks_read_the_same_everywhere():
    def help_of(option: str, command: str) -> str:
        res = CliRunner().invoke(cli, [command, "--help"])
        text = " ".join(res.output.split())
        return re.search(rf"{option} .*?(?= --?[a-z]|$)", text).group(0)

    for option in ("--model", "--method", "--placement", "--format"):
        assert help_of(option, "reconstruct") == help_of(option, "batch") \
            == help_of(option, "live"), option
    assert help_of("--data", "bench") == help_of("--data", "train")


def test_render_writes_a_folder_with_out_and_files_with_o(tmp_path, walk):
    bvh = write_bvh(walk.slice(0, 12), tmp_path / "walk.bvh")
    res = CliRunner().invoke(cli, ["render", str(bvh), "--out", str(tmp_path / "r")])
    assert res.exit_code == 0, res.output
    assert sorted(p.name for p in (tmp_path / "r").iterdir()) == [
        "walk.gif", "walk.html", "walk.mp4"]
    res = CliRunner().invoke(cli, ["render", str(bvh), "-o", str(tmp_path / "one.html")])
    assert res.exit_code == 0 and (tmp_path / "one.html").stat().st_size > 1000
    res = CliRunner().invoke(cli, ["render", str(bvh), "--out", str(tmp_path / "r")])
    assert res.exit_code == 1 and "pass --force" in res.output
    res = CliRunner().invoke(cli, ["render", str(bvh)])
    assert res.exit_code == 2 and "--out DIR or -o FILE" in res.output


def test_export_onnx_defaults_to_the_shipped_model(tmp_path):
    pytest.importorskip("onnx")
    res = CliRunner().invoke(cli, ["export-onnx", "-o", str(tmp_path / "m.onnx")])
    assert res.exit_code == 0, res.output
    assert "learned_right_ankle.npz" in res.output and (tmp_path / "m.onnx").stat().st_size > 1e4


def test_missing_extra_hint_is_quoted_for_the_shell():
    from imuloco.errors import MissingExtraError

    assert "pip install 'imuloco[live]'" in str(MissingExtraError("live mode", "websockets",
                                                                  "live"))


def test_bench_load_takes_comma_separated_folders(tmp_path, monkeypatch):
    """`--load A,B` as its help says (click refused the pair as one missing folder)."""
    from imuloco.lab import loadspeed

    seen = []
    monkeypatch.setattr(loadspeed, "load_benchmark",
                        lambda folders, out, against: seen.extend(folders) or [])
    monkeypatch.setattr(loadspeed, "table", lambda records, against: "")
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir(), b.mkdir()
    res = CliRunner().invoke(cli, ["bench", "--load", f"{a},{b}", "--out", str(tmp_path / "o")])
    assert res.exit_code == 0 and seen == [a, b], res.output
    res = CliRunner().invoke(cli, ["bench", "--load", f"{a},{tmp_path / 'c'}", "--out",
                                   str(tmp_path / "o")])
    assert res.exit_code == 2 and "--load" in res.output and "does not exist" in res.output


def test_warnings_print_on_their_own_lines_once_per_kind_with_a_count(capsys):
    """The console channel: a warning never ends up on a progress bar's line, and repeats of
    a kind are one count at the end."""
    import logging

    from tqdm import tqdm

    from imuloco.app.console import console

    log = logging.getLogger("imuloco.test")
    with console() as handler:
        bar = tqdm(total=3, desc="work")
        for k in range(3):
            log.warning("%s: no samples from %d s", "/long/path/walk.csv", k)
            bar.update()
        log.warning("another kind")
        bar.close()
    err = capsys.readouterr().err
    lines = err.replace("\r", "\n").splitlines()
    assert "/long/path/walk.csv: no samples from 0 s" in lines
    assert "another kind" in lines
    assert err.count("/long/path/walk.csv") == 2  # the first, then the count's line
    assert "(2 more warnings like: /long/path/walk.csv: no samples from 0 s)" in lines
    assert handler.repeats == {("imuloco.test", "%s: no samples from %d s"): 2}


def test_placement_typo_says_what_was_meant_before_reading_anything(tmp_path):
    res = CliRunner().invoke(cli, ["reconstruct", str(tmp_path), "--placement", "right_thig",
                                   "-o", str(tmp_path / "x.bvh")])
    assert res.exit_code != 0
    assert "did you mean 'right_thigh'" in res.output


def test_a_placement_without_a_shipped_model_warns_what_it_falls_back_to(caplog):
    pytest.importorskip("torch")
    from imuloco.app.pipeline import choose_model

    with caplog.at_level("WARNING"):
        choice = choose_model(placement="right_thigh")
    assert choice.source == "fitted" and choice.method.name == "ridge"
    text = caplog.text
    assert "no shipped model for right_thigh" in text and "right_ankle" in text
    assert "docs/results/placements/" in text and "not to be trusted" in text


@pytest.mark.parametrize("command", ["reconstruct", "batch"])
def test_a_bad_column_mapping_is_refused_before_any_work(command, tmp_path):
    log = tmp_path / "other.csv"
    log.write_text("timestamp,ax\n0,1\n")
    out = ["-o", str(tmp_path / "x.bvh")] if command == "reconstruct" else [
        "--out", str(tmp_path / "out")]
    res = CliRunner().invoke(cli, [command, str(log), *out, "--columns", "gyro_q=gz"])
    assert res.exit_code != 0 and "'gyro_q=gz': expected NAME=COLUMN" in res.output
    assert not (tmp_path / "out").exists() and not (tmp_path / "x.bvh").exists()
