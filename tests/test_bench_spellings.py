"""``imuloco bench`` is a group of subcommands (run, speed, fuzz, real, batch, load); the single
command it was keeps working: each old spelling calls the same library function with the same
arguments and prints the same, and the protocol bench writes the same files."""

from __future__ import annotations

import json
from importlib import import_module

import pytest
from click.testing import CliRunner

from imuloco.cli import cli

# (the lab module, the functions the command calls) of each subcommand
CALLS = {
    "run": ("imuloco.lab.bench", "run_bench"), "speed": ("imuloco.lab.speed", "speed_benchmark"),
    "fuzz": ("imuloco.lab.fuzz", "write_fuzz"), "real": ("imuloco.lab.real", "run_real"),
    "batch": ("imuloco.lab.batchbench", "batch_benchmark"),
    "load": ("imuloco.lab.loadspeed", "load_benchmark"),
    "reconstruct": ("imuloco.lab.speed", "reconstruct_speed"),  # bench speed --reconstruct
}
PRINTERS = [("imuloco.lab.report", "table"), ("imuloco.lab.speed", "speed_table"),
            ("imuloco.lab.speed", "reconstruct_table"),
            ("imuloco.lab.real", "summarize"), ("imuloco.lab.real", "table"),
            ("imuloco.lab.batchbench", "markdown"), ("imuloco.lab.loadspeed", "table")]


OUT = ["--out", "{d}/out"]
# (subcommand, old arguments, new arguments) with every option of each mode given; {d} is a
# folder with the empty folders a and b
SPELLINGS = [
    ("run", ["--method", "mean,ridge", "--split", "heldout-styles", "--noise", "clean",
             "--placement", "left_ankle", "--data", "{d}/a", "--limit", "4", "--seed", "3",
             "--seeds", "2", "--up", "y", "--skip-frames", "1", *OUT],
     ["run", "--method", "mean,ridge", "--split", "heldout-styles", "--noise", "clean",
      "--placement", "left_ankle", "--data", "{d}/a", "--limit", "4", "--seed", "3", "--seeds",
      "2", "--up", "y", "--skip-frames", "1", *OUT]),
    ("run", ["--method", "mean", "--split", "cross-dataset", "--train", "{d}/a,{d}/b",
             "--test", "{d}/b", "--fold", "walk,run", *OUT],
     ["run", "--method", "mean", "--split", "cross-dataset", "--train", "{d}/a,{d}/b",
      "--test", "{d}/b", "--fold", "walk,run", *OUT]),
    ("speed", ["--method", "mean", "--speed", "--data", "{d}/a", "--db-frames", "400,800",
               "--against", "HEAD", *OUT],
     ["speed", "--method", "mean", "--data", "{d}/a", "--db-frames", "400,800", "--against",
      "HEAD", *OUT]),
    ("reconstruct", ["--speed", "--reconstruct", "--lengths", "5,10", "--against", "HEAD", *OUT],
     ["speed", "--reconstruct", "--lengths", "5,10", "--against", "HEAD", *OUT]),
    ("reconstruct", ["--speed", "--reconstruct", *OUT], ["speed", "--reconstruct", *OUT]),
    ("fuzz", ["--fuzz", "6", "--readers", "sensorlog,model", "--seed", "2", *OUT],
     ["fuzz", "6", "--readers", "sensorlog,model", "--seed", "2", *OUT]),
    ("real", ["--real", "{d}/a", "--limit", "2", "--baseline", *OUT],
     ["real", "{d}/a", "--limit", "2", "--baseline", *OUT]),
    ("batch", ["--batch", "3", "--method", "mean", "--placement", "left_ankle", *OUT],
     ["batch", "3", "--method", "mean", "--placement", "left_ankle", *OUT]),
    ("batch", ["--batch", "3", *OUT], ["batch", "3", *OUT]),
    ("load", ["--load", "{d}/a,{d}/b", "--against", "HEAD", *OUT],
     ["load", "{d}/a", "{d}/b", "--against", "HEAD", *OUT]),
]


@pytest.mark.parametrize(("command", "old", "new"), SPELLINGS)
def test_old_and_new_spellings_call_the_same_function_and_print_the_same(
        tmp_path, monkeypatch, command, old, new):
    calls: list[tuple] = []

    def recorder(name):
        def record(*args, **kwargs):
            calls.append((name, args, kwargs))
            return [{"motion_type": "all"}] if name == "run_bench" else f"<{name}>"
        return record

    for module, name in [*CALLS.values(), *PRINTERS]:
        monkeypatch.setattr(import_module(module), name, recorder(name))
    (tmp_path / "a").mkdir(), (tmp_path / "b").mkdir()
    outputs = []
    for args in (old, new):
        calls.clear()
        res = CliRunner().invoke(cli, ["bench", *(a.format(d=tmp_path) for a in args)])
        assert res.exit_code == 0, res.output
        outputs.append((res.output, list(calls)))
    assert outputs[0] == outputs[1]
    assert outputs[0][1][0][0] == CALLS[command][1]  # the subcommand's own library function


def test_the_old_spelling_refuses_as_before(tmp_path):
    res = CliRunner().invoke(cli, ["bench", "--out", str(tmp_path)])
    assert res.exit_code == 2 and "Missing option '--method' (or pass --fuzz N" in res.output
    res = CliRunner().invoke(cli, ["bench", "--method", "mean", "--out", str(tmp_path),
                                   "--no-such-option"])
    assert res.exit_code == 2 and "No such option '--no-such-option'" in res.output
    assert "Try 'cli bench --help' for help" in res.output  # not the hidden command's name
    res = CliRunner().invoke(cli, ["bench", "--load", str(tmp_path / "none"), "--out",
                                   str(tmp_path)])
    assert res.exit_code == 2 and "Invalid value for --load: folder" in res.output


def test_bench_help_lists_the_subcommands_and_the_old_options():
    res = CliRunner().invoke(cli, ["bench", "--help"])
    assert res.exit_code == 0
    commands = res.output.split("Commands:")[1].split("Options of")[0].split()
    assert {"run", "speed", "fuzz", "real", "batch", "load"} <= set(commands)
    assert "single" not in commands  # the old spelling's command is hidden
    for option in ("--speed", "--fuzz", "--real", "--batch", "--load", "--db-frames",
                   "--reconstruct", "--lengths"):
        assert option in res.output


def test_the_protocol_bench_writes_the_same_files_either_way(tmp_path):
    """``bench --method ...`` and ``bench run --method ...`` on the bundled sample: the same
    files, the same records but for the timings."""
    # model_bytes too: the saved model's header holds its training time and date, and the
    # compressed file's size moves with them by a byte or two (failed once in .ci/run)
    timings = {"train_s", "offline_fps", "online_latency_ms_p50", "online_latency_ms_p99",
               "model_bytes"}
    args = ["--method", "mean", "--split", "heldout-styles", "--limit", "4", "--out"]
    runner = CliRunner()
    assert runner.invoke(cli, ["bench", *args, str(tmp_path / "old")]).exit_code == 0
    assert runner.invoke(cli, ["bench", "run", *args, str(tmp_path / "new")]).exit_code == 0
    old, new = tmp_path / "old", tmp_path / "new"
    assert sorted(p.name for p in old.iterdir()) == sorted(p.name for p in new.iterdir())

    def records(folder):
        return [{k: v for k, v in r.items() if k not in timings}
                for r in json.loads((folder / "results.json").read_text())]

    assert records(old) == records(new) and len(records(old)) > 1
    assert (old / "per_clip.json").read_text() == (new / "per_clip.json").read_text()


def test_bench_live_runs_the_live_benchmark(tmp_path, monkeypatch):
    """bench live: the load test and the dropouts of imuloco.lab.livebench, as
    benchmarks/live_load.py runs them (that takes minutes: called here with a stand-in)."""
    from imuloco.lab import livebench

    calls = []
    monkeypatch.setattr(livebench, "live_benchmark", lambda *a, **k: calls.append((a, k)) or (
        {"viewers": 3, "server_log": ["x"], "dropped": []}, {"runs": 9, "details": [1]}))
    res = CliRunner().invoke(cli, ["bench", "live", "--viewers", "3", "--seconds", "1.5",
                                   "--no-abuse", "--out", str(tmp_path)])
    assert res.exit_code == 0, res.output
    assert calls == [((tmp_path, 3, 1.5), {"abuse": False})]
    assert '"viewers": 3' in res.output and '"runs": 9' in res.output
    assert "server_log" not in res.output and "details" not in res.output


def test_bench_live_without_the_live_extra(tmp_path, monkeypatch):
    import sys

    for name in [*sys.modules]:  # imported by an earlier test: imported anew, without it
        if name.startswith(("websockets", "imuloco.lab.livebench", "imuloco.app.live.server")):
            monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, "websockets", None)
    res = CliRunner().invoke(cli, ["bench", "live", "--out", str(tmp_path)])
    assert res.exit_code == 1 and "pip install 'imuloco[live]'" in res.output, res.output
