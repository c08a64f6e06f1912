"""The ``imuloco`` command line: parses arguments and calls library functions.

Each command is a thin wrapper; the work lives in the library so that tests call it too.
Errors the user can cause are the library's (:mod:`imuloco.errors`); :class:`Commands` turns
any of them into one ``Error: ...`` line. Options several commands share are declared once
below. A command that writes one file takes ``-o FILE``, one that writes a folder ``--out DIR``.

Importing this module and building any command's ``--help`` imports click, the standard
library and the few light modules imported below, never numpy, scipy or the methods
(``imuloco reconstruct --help`` took 1.9 s for its help texts' sake;
``tests/test_cli_startup.py`` checks it). Each command imports the heavy modules it needs when
it runs.
"""

from __future__ import annotations

import json
import math
import os
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

from imuloco.app.console import console
from imuloco.core.bodymap import PARTS
from imuloco.errors import ImulocoError, InputError, MissingExtraError, UnknownNameError
from imuloco.io.atomic import FULL, atomic_write, check_output, check_outputs
from imuloco.limits import (
    FORMATS,
    MAX_CALIBRATE_S,
    MAX_HEIGHT_M,
    MAX_RATE,
    MIN_CALIBRATE_S,
    MIN_HEIGHT_M,
    MIN_RATE,
    RIG_NAMES,
)


class Commands(click.Group):
    """The command group: an :class:`~imuloco.errors.ImulocoError` raised by any command ends
    it with ``Error: <message>`` on a line of its own (after any progress bar) and exit
    status 1, instead of a traceback; so does a full disk (``Error: no space left on device
    writing FILE``)."""

    def invoke(self, ctx: click.Context) -> Any:
        with console():  # warnings on their own lines, each kind once
            try:
                return super().invoke(ctx)
            except ImulocoError as e:
                _end_progress_bars()
                raise click.ClickException(str(e)) from None
            except OSError as e:  # a full disk outside imuloco.io.atomic's writes (a cache, ...)
                if e.errno not in FULL:
                    raise
                _end_progress_bars()
                where = f" writing {e.filename}" if e.filename else ""
                raise click.ClickException(f"{os.strerror(e.errno).lower()}{where}") from None


def _end_progress_bars() -> None:
    """Close the progress bars an error interrupted, so that the error starts a new line."""
    tqdm = sys.modules.get("tqdm.std")
    if tqdm is not None:  # a bar can only be open when tqdm was imported
        for bar in list(getattr(tqdm.tqdm, "_instances", ())):
            bar.close()


@click.group(cls=Commands)
@click.version_option(package_name="imuloco")
def cli() -> None:
    """Full-body locomotion reconstruction from one body-worn inertial sensor."""


def _options(*decorators: Callable) -> Callable:
    """One decorator applying ``decorators`` in order (options shared by several commands)."""
    def apply(f: Callable) -> Callable:
        for d in reversed(decorators):
            f = d(f)
        return f
    return apply


class _Range(click.FloatRange):
    """A finite number in a range: click's FloatRange lets NaN through (it fails every
    comparison) and inf where a side is open, which then broke deep inside (``int(nan)``)."""

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None
                ) -> Any:
        number = super().convert(value, param, ctx)
        if not math.isfinite(number):
            self.fail(f"{value!r} is not a finite number", param, ctx)
        return number


class _ZeroOrRange(_Range):
    """0, or a finite number in the range (``--piece-seconds 0``: one piece)."""

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None
                ) -> Any:
        try:
            if float(value) == 0:
                return 0.0
        except (TypeError, ValueError):
            pass  # the range's own message
        return super().convert(value, param, ctx)


def _existing_file(**kw: Any) -> click.Path:
    return click.Path(exists=True, dir_okay=False, path_type=Path, **kw)


def _file(**kw: Any) -> click.Path:
    return click.Path(dir_okay=False, path_type=Path, **kw)


def _folder(**kw: Any) -> click.Path:
    return click.Path(file_okay=False, path_type=Path, **kw)


def _existing_folder(**kw: Any) -> click.Path:
    return click.Path(exists=True, file_okay=False, path_type=Path, **kw)


SPLITS = ("random-clips", "heldout-styles")
MIRROR_CLIPS = 20  # clips that fit a mirrored model's sensor-axis map (Learned.mirrored)
NOISES = ("clean", "phone", "imu")

def _placements(ctx: click.Context, param: click.Parameter, value: str) -> str:
    """``--placement`` as given, once it names at least one preset (``,`` named none and
    failed in numpy), each known (an unknown one was found only after the data was read)."""
    from imuloco.sensors.placement import get_placement  # heavy (numpy, scipy): on use

    if not _csv(value):
        raise click.BadParameter(f"expected placement preset(s), got {value!r}")
    for name in _csv(value):
        get_placement(name)  # UnknownNameError: the command's one-line error
    return value


force_option = click.option("--force", is_flag=True, help="Replace existing output files.")
no_fallback_option = click.option(
    "--no-fallback", is_flag=True,
    help="Keep the model's pose everywhere: do not move the parts the sensor cannot see "
         "toward a neutral pose where the motion is unfamiliar, nor the body toward the "
         "standing pose where the sensor is still (a report's 'fallback' says what the "
         "fallback did).")
placement_option = click.option("--placement", default="right_ankle", show_default=True,
                                callback=_placements,
                                help="Sensor placement preset(s), comma separated.")
noise_option = click.option("--noise", type=click.Choice(NOISES), default="phone",
                            show_default=True, help="Noise preset of the simulated sensors.")
DATA_HELP = ("Folder(s) of clips, repeatable or comma separated; several become one set on "
             "the first one's skeleton and frame rate (others retargeted) [default: the "
             "bundled sample].")


data_options = _options(
    click.option("--data", "data_items", multiple=True, help=DATA_HELP),
    click.option("--limit", type=click.IntRange(min=1), default=None,
                 help="Read at most N clips per folder (quick runs)."),
    click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True),
)
# the model a reconstruction uses (reconstruct, batch, demo, live): imuloco.app.pipeline
model_options = _options(
    click.option("--model", "model_path", type=_existing_file(), default=None,
                 help="Model file from `imuloco train` [default: the shipped pretrained "
                      "model]."),
    click.option("--method", "method_name", default=None,
                 help="Method to use without --model (its shipped model, or fitted on the "
                      "bundled sample) [default: learned, else the best available baseline]."),
)
# reading phone logs (reconstruct, batch, live --replay): imuloco.sensors.reallog
log_options = _options(
    click.option("--placement", default="right_ankle", show_default=True,
                 callback=_placements,
                 help="Where the phone was worn (placement preset): right_ankle or "
                      "left_ankle for a shin, right_foot or left_foot for a shoe IMU, "
                      "lower_back at L5 (these three need the [gait] extra)."),
    click.option("--format", "fmt", default="auto", show_default=True,
                 type=click.Choice(("auto", *FORMATS)),
                 help="Sensor log format."),
)
platform_option = click.option(
    "--platform", type=click.Choice(["ios", "android"]), default=None,
    help="Phone of a Sensor Logger export [default: from its Metadata.csv, else guessed with "
         "a warning].")
height_option = click.option(
    "--height", type=_Range(MIN_HEIGHT_M, MAX_HEIGHT_M),
    default=None, metavar="METRES",
    help="The wearer's body height: the skeleton and every length and speed in their "
         "proportions [default: the training skeleton's].")
skeleton_option = click.option(
    "--skeleton", "skeleton", type=_existing_file(), default=None,
    help="A BVH of your rig: the motion is retargeted onto it (its joint names, offsets and "
         "rest pose) [default: the model's training skeleton].")
rig_option = click.option(
    "--rig", type=click.Choice(RIG_NAMES), default=None,
    help="Joint names, hierarchy and T-pose rest of the written motion (the same motion on "
         "each): bvh-default (the model's joint names), mixamo, unreal (UE4 mannequin), unity "
         "(Humanoid), or model (the training skeleton's own rest pose) [default: bvh-default; "
         "not with --skeleton].")
columns_option = click.option(
    "--columns", "columns", default=None, metavar="NAME=COLUMN,...",
    callback=lambda ctx, param, value: _parse_columns(value),
    help="A CSV's own column names, read as a generic log: e.g. "
         "time=timestamp,acc_x=ax,acc_y=ay,acc_z=az,gyro_x=gx,gyro_y=gy,gyro_z=gz (units and "
         "the time unit are detected).")


def _parse_sensors(ctx: click.Context, param: click.Parameter, values: tuple[str, ...]
                   ) -> list[tuple[str, Path]]:
    """``--sensor PLACEMENT=FILE`` (repeatable) as (placement, file) pairs, each file
    existing, before any work (:func:`imuloco.sensors.multi.parse_sensor`)."""
    if not values:
        return []
    from imuloco.sensors.multi import parse_sensor  # numpy, scipy: on use (--help stays fast)

    out = []
    for v in values:
        try:
            name, file = parse_sensor(v)
        except ImulocoError as e:
            raise click.BadParameter(str(e), param_hint="--sensor") from None
        if not file.exists():
            raise click.BadParameter(f"{file}: no such file or folder", param_hint="--sensor")
        out.append((name, file))
    return out


sensor_option = click.option(
    "--sensor", "sensors", multiple=True, metavar="PLACEMENT=FILE", callback=_parse_sensors,
    help="A further sensor's log (repeatable), e.g. left_wrist=watch.csv: put on the "
         "recording's clock by Unix timestamps, else by a stomp at the start (stand still, "
         "stomp twice); the shipped model reading all the sensors is chosen.")


def _parse_columns(value: str | None) -> dict[str, str] | None:
    """``--columns`` as a mapping (:func:`imuloco.io.sensorlog.parse_columns`), before any
    work."""
    from imuloco.io.sensorlog import parse_columns  # heavy (numpy): on use

    return parse_columns(value) if value else None


calibrate_option = click.option("--no-calibrate", is_flag=True,
                                help="Skip the phone-on-leg calibration.")
# how motion files are read (info, phases, bench, train): read_bvh's options
_reading_options = _options(
    click.option("--up", type=click.Choice(["auto", "y", "z"]), default="auto",
                 show_default=True, help="Vertical axis of the motion files; Z-up files are "
                                         "turned Y up (auto: detected from the animated body)."),
    click.option("--skip-frames", type=click.IntRange(min=0), default=0, show_default=True,
                 help="Drop this many leading frames of each motion file (a prepended "
                      "T-pose)."),
)


def _num(value: float | None, digits: int) -> str:
    """A number rounded to what it means (``digits`` decimals), ``–`` when unknown."""
    return "–" if value is None else f"{value:.{digits}f}"


def _units_option(f):
    """``--units m|cm``: the length unit of written BVH files."""
    return click.option("--units", "units", type=click.Choice(["cm", "m"]), default="cm",
                        show_default=True,
                        help="Length unit of the written BVH (Blender: import a cm file with "
                             "scale 0.01, an m file with scale 1).")(f)


@cli.command()
@click.argument("file", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--json", "as_json", is_flag=True, help="Print JSON instead of text.")
@_reading_options
def info(file: Path, as_json: bool, up: str, skip_frames: int) -> None:
    """Joints, frames, fps, duration and the body map found for a motion FILE."""
    from imuloco.io.motionfile import read_motion  # heavy: on use, so that --help stays fast

    motion = read_motion(file, up=up, skip_frames=skip_frames)
    sk = motion.skeleton
    report = {
        "file": str(file), "joints": sk.num_joints, "names": sk.names,
        "frames": motion.num_frames, "fps": motion.fps, "duration_s": round(motion.duration, 3),
        "body_map": sk.body_map,
        "unmapped_parts": [p for p in PARTS
                           if p not in (sk.body_map or {})],
    }
    if as_json:
        click.echo(json.dumps(report, indent=2))
        return
    for key, value in report.items():
        click.echo(f"{key:>15}: {value}")


@cli.command()
@click.argument("motion_file", metavar="MOTION", type=click.Path(exists=True, dir_okay=False,
                                                                 path_type=Path))
@click.option("--json", "as_json", is_flag=True, help="Print JSON instead of text.")
@click.option("--reference", type=click.Choice(["right", "left"]), default="right",
              show_default=True, help="Leg whose 8-phase cycle is labelled.")
@_reading_options
def phases(motion_file: Path, as_json: bool, reference: str, up: str, skip_frames: int) -> None:
    """Per-frame foot contacts and gait phases, and step events, of a MOTION file."""
    # heavy: on use, so that --help stays fast
    from imuloco.io.motionfile import read_motion
    from imuloco.phases import gait_phases

    report = gait_phases(read_motion(motion_file, up=up, skip_frames=skip_frames),
                         reference=reference).to_dict()
    if as_json:
        click.echo(json.dumps(report))
        return
    c = report["contacts"]
    click.echo(f"{'frame':>5} {'time_s':>7}  LH LT RH RT  {'support':<7} {'eom2014':<10} phase")
    for t in range(report["frames"]):
        flags = "  ".join(str(c[k][t]) for k in ("left_heel", "left_toe", "right_heel",
                                                 "right_toe"))
        click.echo(f"{t:>5} {t / report['fps']:>7.3f}   {flags}  {report['support'][t]:<7} "
                   f"{report['eom2014'][t]:<10} {report['phase'][t]}")
    for foot in ("left", "right"):
        click.echo(f"{foot} strikes: {report['steps'][foot]}")
    click.echo(f"cadence: {report['cadence_spm']} steps/min; flight frames: "
               f"{len(report['flight_frames'])}")


@cli.command()
def methods() -> None:
    """List the reconstruction methods with one line each (without importing them)."""
    from imuloco.methods.registry import describe, method_names  # 50 ms (ast): on use
    found = [describe(name) for name in method_names()]
    width = max(len(m.name) for m in found)
    for m in found:
        online = "online" if m.supports_online else "offline"
        hint = f" (needs {m.missing}: pip install 'imuloco[{m.extra}]')" if m.missing else ""
        click.echo(f"{m.name:<{width}}  [{online:>7}]  {m.summary}{hint}")


def _csv(value: str | None) -> list[str]:
    return [v.strip() for v in (value or "").split(",") if v.strip()]


def _whole_numbers(value: str | None, hint: str) -> list[int]:
    """Comma separated positive whole numbers of the option ``hint``."""
    try:
        numbers = [int(v) for v in _csv(value)]
    except ValueError:
        numbers = [0]
    if any(n < 1 for n in numbers):
        raise click.BadParameter(f"expected positive whole numbers, comma separated, got "
                                 f"{value!r}", param_hint=hint)
    return numbers


def _folders(values: tuple[str, ...], hint: str = "--data") -> list[Path] | None:
    """Folders given as a repeatable and/or comma separated option ``hint``; each must
    exist."""
    folders = [Path(v) for item in values for v in _csv(item)]
    for f in folders:
        if not f.is_dir():
            raise click.BadParameter(f"folder {f} does not exist", param_hint=hint)
    return folders or None


class _Bench(click.Group):
    """``imuloco bench SUBCOMMAND``. The single command ``bench`` was keeps working: an
    invocation that starts with an option other than ``--help`` (``bench --method M --out
    DIR``, ``bench --speed ...``, ``--fuzz N``, ``--real DIR``, ``--batch N``, ``--load DIR``)
    runs the hidden :data:`_OLD` command, which takes the old options and invokes the
    subcommand they name; ``bench --help`` lists those options after the subcommands."""

    def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        if args and args[0].startswith("-") and args[0] not in ctx.help_option_names:
            args = [_OLD, *args]
        return super().parse_args(ctx, args)

    def format_options(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        super().format_options(ctx, formatter)
        old = self.commands[_OLD]
        with formatter.section("Options of the single-command spelling"):
            formatter.write_text("imuloco bench OPTIONS, as before the subcommands: the "
                                 "protocol bench (run), or --speed, --fuzz N, --real DIR, "
                                 "--batch N or --load DIR.")
            formatter.write_paragraph()
            formatter.write_dl([p.get_help_record(ctx) for p in old.params])


_OLD = "single"  # the hidden command of the old spelling


class _OldContext(click.Context):
    @property
    def command_path(self) -> str:
        return self.parent.command_path if self.parent else super().command_path


class _OldCommand(click.Command):
    """The old spelling's command: its usage lines and errors say ``imuloco bench``, as
    before, not the hidden command's name."""

    context_class = _OldContext


@cli.group(cls=_Bench)
def bench() -> None:
    """Measure the methods and the app: the protocol bench (run), speed, fuzzing, real
    data, batch throughput, loading."""


def _out_option(files: str) -> Callable:
    return click.option("--out", type=_folder(), required=True, help=f"Folder for {files}.")


_split_option = click.option(
    "--split", "split_name", default="random-clips", show_default=True,
    type=click.Choice([*SPLITS, "heldout-contents", "cross-dataset", "heldout-actions"]),
    help="Protocol (imuloco.lab.protocols); cross-dataset takes --train/--test.")
_protocol_options = _options(  # bench run's besides --method, --out
    click.option("--train", "train_items", multiple=True,
                 help="cross-dataset: training folder(s), repeatable or comma separated."),
    click.option("--test", "test_items", multiple=True, help="cross-dataset: the test folder."),
    click.option("--seeds", "n_seeds", type=click.IntRange(min=1), default=1, show_default=True,
                 help="Train each method with N seeds (seed, seed+1, ...): mean and spread."),
    click.option("--fold", "fold_names", default=None, metavar="CONTENT[,CONTENT]",
                 help="heldout-contents, heldout-actions: run only these folds (left-out "
                      "contents)."),
)
# everything the protocol bench takes besides --method (bench run, and the old single bench)
_protocol_bench_options = _options(_split_option, noise_option, placement_option, data_options,
                                   _protocol_options, _out_option("results.json and results.md"))
METHODS_HELP = ("Method name(s), comma separated (see `imuloco methods`); a variant as "
                "NAME[key=value;key=value], e.g. eom2014[variant=mlp-no-hmm]")


@bench.command("run", short_help="The protocol bench: train methods, score their test clips.")
@click.option("--method", "method_names", required=True, help=METHODS_HELP + ".")
@_protocol_bench_options
@_reading_options
def bench_run(method_names: str, split_name: str, noise: str, placement: str,
              data_items: tuple[str, ...], limit: int | None, seed: int,
              train_items: tuple[str, ...], test_items: tuple[str, ...], n_seeds: int,
              fold_names: str | None, out: Path, up: str, skip_frames: int) -> None:
    """Train methods, reconstruct every test clip and write results.json and results.md."""
    # heavy (numpy, the methods): on use, so that --help stays fast (as in each bench)
    from imuloco.lab.bench import run_bench
    from imuloco.lab.report import COLUMNS, table

    records = run_bench(_csv(method_names), split_name, noise, _csv(placement),
                        _folders(data_items), out, limit, seed, progress=True, seeds=n_seeds,
                        train=_folders(train_items, "--train"),
                        test=_folders(test_items, "--test"), up=up, skip_frames=skip_frames,
                        only_folds=_csv(fold_names) or None)
    click.echo(table([r for r in records if r["motion_type"] == "all"], COLUMNS))
    click.echo(f"wrote {out / 'results.json'} and {out / 'results.md'}")


@bench.command("speed", short_help="Online reconstruction time against database size.")
@click.option("--method", "method_names", default=None,
              help=METHODS_HELP + " (required but with --reconstruct).")
@click.option("--data", "data_items", multiple=True,
              help="Folder of clips to time on (the first one given) [default: the bundled "
                   "sample].")
@click.option("--db-frames", default=None, help="Database sizes in frames, comma separated.")
@click.option("--against", default=None, metavar="REV",
              help="Also time each method's code at this git commit, in the same run.")
@click.option("--reconstruct", "reconstruct_row", is_flag=True,
              help="Instead: time `imuloco reconstruct --report` per shipped placement and "
                   "length (one thread and the default; wall, CPU, real-time factor, peak "
                   "memory; --against: the old code's too); writes reconstruct_speed.md/.json.")
@click.option("--lengths", default="60,600,3600", show_default=True,
              help="With --reconstruct: recording lengths in seconds, comma separated.")
@_out_option("speed.json and speed.md")
def bench_speed(method_names: str | None, data_items: tuple[str, ...], db_frames: str | None,
                against: str | None, reconstruct_row: bool, lengths: str, out: Path) -> None:
    """Time online reconstruction against database size (imuloco.lab.speed); write
    speed.json and speed.md."""
    from imuloco.lab.speed import (
        reconstruct_speed,
        reconstruct_table,
        speed_benchmark,
        speed_table,  # heavy: on use
    )

    if reconstruct_row:
        try:
            seconds = [float(v) for v in _csv(lengths)]
        except ValueError:
            seconds = []
        if not seconds or not all(0 < v < float("inf") for v in seconds):
            raise click.BadParameter(f"expected positive seconds, comma separated, got "
                                     f"{lengths!r}", param_hint="--lengths")
        click.echo(reconstruct_table(reconstruct_speed(seconds, against=against, out=out,
                                                       progress=True)))
        click.echo(f"wrote {out / 'reconstruct_speed.json'} and .md")
        return
    if not method_names:
        raise click.UsageError("Missing option '--method' (or pass --reconstruct).")
    data = _folders(data_items)
    frames = _whole_numbers(db_frames, "--db-frames") or None
    click.echo(speed_table(speed_benchmark(_csv(method_names), out, data[0] if data else None,
                                           frames, against=against), data[0] if data else None))


@bench.command("fuzz", short_help="Malformed inputs read by each reader.")
@click.argument("inputs", metavar="N", type=click.IntRange(1))
@click.option("--readers", default=None, help="Readers, comma separated [default: all].")
@click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True)
@_out_option("fuzz.md and fuzz.json")
def bench_fuzz(inputs: int, readers: str | None, seed: int, out: Path) -> None:
    """Read N generated malformed inputs per reader (imuloco.lab.fuzz) and write fuzz.md and
    fuzz.json."""
    from imuloco.lab.fuzz import READERS, write_fuzz  # heavy: on use

    chosen = tuple(_csv(readers)) or READERS
    unknown = sorted(set(chosen) - set(READERS))
    if unknown:
        raise click.BadParameter(f"unknown reader(s) {unknown}; expected {list(READERS)}",
                                 param_hint="--readers")
    click.echo(write_fuzz(inputs, out, chosen, seed=seed, progress=True))


@bench.command("real", short_help="The gait protocol on real IMU recordings with references.")
@click.argument("real_dir", metavar="DIR",
                type=click.Path(exists=True, file_okay=False, path_type=Path))
@click.option("--limit", type=click.IntRange(min=1), default=None,
              help="Read at most N trials per data set (quick runs).")
@click.option("--baseline", is_flag=True,
              help="Also measure the gait of the motion the placement's shipped model "
                   "reconstructs (the right-ankle one where it has none).")
@_out_option("real.json, real.csv and README.md")
def bench_real(real_dir: Path, limit: int | None, baseline: bool, out: Path) -> None:
    """The real-data gait protocol on the data sets in DIR (real IMUs with references,
    imuloco.lab.real)."""
    # heavy: on use
    from imuloco.app.pipeline import GAIT_EXTRA, require_extras
    from imuloco.lab.real import run_real, summarize, table

    for p in GAIT_EXTRA:  # feet and lower backs
        require_extras(p)
    rows = run_real(real_dir, out, limit, baseline, progress=True)
    click.echo(table(summarize(rows)))
    click.echo(f"wrote {out / 'real.json'}, real.csv and README.md")


@bench.command("batch", short_help="`imuloco batch` throughput on N simulated walkers.")
@click.argument("walkers", metavar="N", type=click.IntRange(1))
@click.option("--method", "method_names", default=None,
              help="Method whose model the walkers are reconstructed with [default: the "
                   "shipped model].")
@placement_option
@_out_option("batch_bench.md and batch_bench.json")
def bench_batch(walkers: int, method_names: str | None, placement: str, out: Path) -> None:
    """The batch benchmark (imuloco.lab.batchbench) on N simulated walkers of 60 s."""
    from imuloco.lab.batchbench import batch_benchmark, markdown  # heavy: on use

    click.echo(markdown(batch_benchmark(walkers, out, method=method_names,
                                        placement=placement)))
    click.echo(f"wrote {out / 'batch_bench.json'} and {out / 'batch_bench.md'}")


@bench.command("load", short_help="Loading time of motion folders.")
@click.argument("load_dirs", metavar="DIR...", nargs=-1, required=True)
@click.option("--against", default=None, metavar="REV",
              help="Also time the BVH reader of this git commit and report the largest "
                   "difference of its Motions from today's.")
@_out_option("load.json and load.md")
def bench_load(load_dirs: tuple[str, ...], against: str | None, out: Path) -> None:
    """Time loading the motion folders DIR (repeat or comma-separate): numpy parse, reader,
    cold and warm cache."""
    from imuloco.lab.loadspeed import load_benchmark, table  # heavy: on use

    folders = _folders(load_dirs, "DIR")
    click.echo(table(load_benchmark(folders, out, against), against))
    click.echo(f"wrote {out / 'load.json'} and {out / 'load.md'}")


@bench.command("live", short_help="The live server under load, and after sensor dropouts.")
@click.option("--viewers", type=click.IntRange(min=1), default=100, show_default=True,
              help="Browser viewers connected at once.")
@click.option("--seconds", type=_Range(0, min_open=True), default=20.0, show_default=True,
              help="How long the phone streams.")
@click.option("--no-abuse", is_flag=True,
              help="The phone only streams (no oversized, flooding or extra clients).")
@_out_option("load.json and dropout.json")
def bench_live(viewers: int, seconds: float, no_abuse: bool, out: Path) -> None:
    """Load-test the live server on 127.0.0.1 (a simulated phone and --viewers browsers, with
    abusive messages) and measure the recovery after sensor dropouts (imuloco.lab.livebench;
    needs the [live] extra; Linux)."""
    try:  # heavy: on use; and the [live] extra
        from imuloco.lab.livebench import live_benchmark, summaries
    except ModuleNotFoundError as e:
        if (e.name or "").split(".")[0] != "websockets":
            raise
        raise MissingExtraError("the live bench", e.name, "live") from None

    click.echo(summaries(*live_benchmark(out, viewers, seconds, abuse=not no_abuse)))
    click.echo(f"wrote {out / 'load.json'} and {out / 'dropout.json'}")


@bench.command(_OLD, cls=_OldCommand, hidden=True)
@click.option("--method", "method_names", default=None,
              help=METHODS_HELP + " [required but with --batch, which defaults to the shipped "
                                  "model].")
@_protocol_bench_options
@click.option("--speed", is_flag=True, help="Instead: bench speed.")
@click.option("--db-frames", default=None,
              help="With --speed: database sizes in frames, comma separated.")
@click.option("--reconstruct", "reconstruct_row", is_flag=True,
              help="With --speed: time `imuloco reconstruct --report` instead (bench speed "
                   "--reconstruct).")
@click.option("--lengths", default="60,600,3600", show_default=True,
              help="With --speed --reconstruct: recording lengths in seconds, comma separated.")
@click.option("--fuzz", type=click.IntRange(1), default=None, metavar="N",
              help="Instead: bench fuzz N.")
@click.option("--readers", default=None,
              help="With --fuzz: readers, comma separated [default: all].")
@click.option("--real", "real_dir", type=click.Path(exists=True, file_okay=False, path_type=Path),
              default=None, help="Instead: bench real DIR.")
@click.option("--baseline", is_flag=True,
              help="With --real: also measure the gait of the motion the placement's shipped "
                   "model reconstructs (the right-ankle one where it has none).")
@click.option("--batch", "batch_walkers", type=click.IntRange(1), default=None, metavar="N",
              help="Instead: bench batch N.")
@click.option("--load", "load_dirs", multiple=True, metavar="DIR",
              help="Instead: bench load DIR (repeat or comma-separate).")
@click.option("--against", default=None, metavar="REV",
              help="With --load: also time the BVH reader of this git commit and report the "
                   "largest difference of its Motions from today's; with --speed: also each "
                   "method's code at this commit, in the same run.")
@_reading_options
@click.pass_context
def bench_single(ctx: click.Context, method_names: str | None, speed: bool,
                 fuzz: int | None, real_dir: Path | None, batch_walkers: int | None,
                 load_dirs: tuple[str, ...], **options: Any) -> None:
    """The single command bench was: the first of --fuzz, --real, --batch, --load and
    --speed given names the subcommand, else it is bench run; the options that subcommand
    also takes are passed on."""

    def run(command: click.Command, **given: Any) -> None:
        names = {p.name for p in command.params}
        ctx.invoke(command, **{k: v for k, v in options.items() if k in names}, **given)

    if fuzz is not None:
        return run(bench_fuzz, inputs=fuzz)
    if real_dir is not None:
        return run(bench_real, real_dir=real_dir)
    if batch_walkers is not None:
        return run(bench_batch, walkers=batch_walkers, method_names=method_names)
    if load_dirs:
        return run(bench_load, load_dirs=tuple(map(str, _folders(load_dirs, "--load"))))
    if speed and options["reconstruct_row"]:  # bench speed --reconstruct needs no --method
        return run(bench_speed, method_names=method_names)
    if not method_names:
        raise click.UsageError("Missing option '--method' (or pass --fuzz N, --batch N, "
                               "--load DIR or --real DIR).")
    return run(bench_speed if speed else bench_run, method_names=method_names)


@cli.command()
@click.argument("ground_truth", type=_existing_file())
@click.argument("reconstructed", type=_existing_file())
@click.option("--json", "as_json", is_flag=True, help="Print JSON instead of text.")
def evaluate(ground_truth: Path, reconstructed: Path, as_json: bool) -> None:
    """Print the metrics of a RECONSTRUCTED motion against its GROUND_TRUTH (same skeleton;
    the longer is cut to the shorter's length)."""
    from imuloco.measures.metrics import evaluate_files  # heavy: on use

    values, note = evaluate_files(ground_truth, reconstructed)
    if note:
        click.echo(note, err=True)
    if as_json:
        click.echo(json.dumps(values, indent=2))
        return
    for key, value in values.items():
        click.echo(f"{key:>20}: {value:.4g}")


@cli.command()
@click.option("--method", "method_name", required=True, help="Method name (`imuloco methods`).")
@data_options
@placement_option
@noise_option
@click.option("--split", "split_name", type=click.Choice(SPLITS), default=None,
              help="Train on this split's training part only [default: all].")
@click.option("--param", "params", multiple=True, metavar="KEY=VALUE",
              help="A hyperparameter of the method (repeatable), e.g. --param epochs=4.")
@click.option("-o", "--output", type=_file(), required=True, help="Model file to write (.npz).")
@click.option("--mirrored", "mirrored_path", type=_file(), default=None,
              help="Also write the model of the other side's placements (right <-> left): "
                   "the same weights reading mirrored signals (learned only).")
@force_option
@_reading_options
def train(method_name: str, data_items: tuple[str, ...], placement: str, noise: str,
          split_name: str | None, params: tuple[str, ...], limit: int | None, seed: int,
          output: Path, mirrored_path: Path | None, force: bool, up: str,
          skip_frames: int) -> None:
    """Fit a method on motion clips with simulated sensors and save the model.

    Writes OUTPUT, and for methods that keep a training history (``learned``) its losses per
    epoch beside it as OUTPUT.history.json and, with matplotlib, OUTPUT.curves.png.
    """
    # heavy (numpy, the methods): on use, so that --help stays fast
    from imuloco.lab.bench import data_label, load_data
    from imuloco.lab.protocols import split
    from imuloco.methods import get_method, method_class
    from imuloco.methods.registry import parse_params

    check_outputs([output, mirrored_path], force)
    if mirrored_path is not None and not hasattr(method_class(method_name), "mirrored"):
        raise click.UsageError(f"--mirrored: method {method_name!r} has no mirrored model "
                               "(only learned)")
    method_class(method_name)  # an unknown method is refused as such, not as --param
    try:  # unknown names, kinds and ranges, as bench checks them
        method = get_method(method_name, **parse_params(params, "--param"))
    except (UnknownNameError, InputError) as e:
        raise click.BadParameter(str(e), param_hint="--param") from None
    data = _folders(data_items)
    db = load_data(data, limit, progress=True, up=up, skip_frames=skip_frames)
    if split_name is not None:
        db = split(db, split_name)[0]
    placements = _csv(placement)
    try:
        method.fit(db, placements, noise, seed, progress=True)
    except (ValueError, TypeError) as e:
        if not params:
            raise
        raise click.BadParameter(f"{e} (rejected by {method_name})", param_hint="--param"
                                 ) from None
    method.protocol_.update(data="bundled sample" if data is None else data_label(data),
                            split=split_name or "all")
    seconds = method.protocol_["train_seconds"]
    method.save(output, overwrite=True)  # checked before training
    click.echo(f"trained {method_name} on {len(db)} clips ({db.num_frames} frames) in "
               f"{seconds / 60:.1f} min; wrote {output}")
    for path in method.write_training_report(output):
        click.echo(f"wrote {path}")
    if mirrored_path is not None:
        _save_mirrored(method, db, mirrored_path)


def _save_mirrored(model, db, path: Path) -> None:
    """Write ``model``'s mirror (the other side's placements), fitted on a spread of ``db``'s
    clips, to ``path`` (checked for overwriting by the caller before any work)."""
    try:
        other = model.mirrored(db.clips[:: max(len(db) // MIRROR_CLIPS, 1)])
    except ValueError as e:
        raise click.UsageError(f"--mirrored: {e}") from None
    other.save(path, overwrite=True)
    click.echo(f"wrote {path} (for {', '.join(other.placements_)})")


@cli.command()
@click.argument("members", nargs=-1, required=True, type=_existing_file())
@click.option("-o", "--output", type=_file(), required=True, help="Model file to write (.npz).")
@click.option("--mirrored", "mirrored_path", type=_file(), default=None,
              help="Also write the ensemble of the other side's placements (right <-> left).")
@click.option("--data", "data_items", multiple=True, help=DATA_HELP)
@click.option("--limit", type=click.IntRange(min=1), default=None,
              help="Read at most N clips per folder.")
@force_option
@_reading_options
def ensemble(members: tuple[Path, ...], output: Path, mirrored_path: Path | None,
             data_items: tuple[str, ...], limit: int | None, force: bool, up: str,
             skip_frames: int) -> None:
    """Average learned models of one recipe trained from other seeds (``train --param
    seed=K``) into one model (a deep ensemble) and write it. Its novelty is the members' mean
    (each against its own reference), and it scores each frame by how much its members disagree
    (spread_m, for `imuloco calibrate`); --data gives the motion --mirrored fits its mirror on.

    Members train independently, so they can run at once on several cores or machines.
    """
    # heavy (the methods, torch): on use, so that --help stays fast
    from imuloco.lab.bench import load_data
    from imuloco.methods import load_model
    from imuloco.methods.learned.method import ensemble as combine

    check_outputs([output, mirrored_path], force, inputs=members)
    try:
        model = combine([load_model(p) for p in members])
    except ImulocoError as e:
        raise click.UsageError(f"{e} ({', '.join(map(str, members))})") from None
    model.save(output, overwrite=True)  # checked above
    click.echo(f"wrote {output}: {len(members)} members")
    for path in model.write_training_report(output):
        click.echo(f"wrote {path}")
    if mirrored_path is not None:
        _save_mirrored(model, load_data(_folders(data_items), limit, progress=True, up=up,
                                        skip_frames=skip_frames), mirrored_path)


@cli.command("export-onnx")
@click.option("--model", "model_path", type=_existing_file(), default=None,
              help="A model file written by `imuloco train` (method learned) [default: the "
                   "shipped learned_right_ankle.npz].")
@click.option("-o", "--output", type=_file(), required=True, help="ONNX file to write.")
@force_option
def export_onnx_command(model_path: Path | None, output: Path, force: bool) -> None:
    """Export a learned model to ONNX (per-frame network with its recurrent state)."""
    # heavy (the methods): on use, so that --help stays fast
    from imuloco.app.pipeline import shipped_model
    from imuloco.methods import load_model

    if model_path is None:
        model_path = shipped_model("learned", "right_ankle")
        if model_path is None:
            raise click.UsageError("no shipped learned model in this installation: give "
                                   "--model")
    check_output(output, force, inputs=[model_path])
    model = load_model(model_path)
    if model.name != "learned":
        raise click.UsageError(f"{model_path}: method {model.name!r} has no ONNX export; "
                               "only `learned` models do")
    from imuloco.methods.learned.export import export_onnx  # torch ([deep]): learned only

    path = export_onnx(model, output, overwrite=True)  # checked above; written atomically
    click.echo(f"wrote {path} (from {model_path})")


@cli.command()
@click.argument("results", nargs=-1, required=True, type=_existing_folder())
@click.option("--method", "method_spec", default=None,
              help="The method's results to use, its spec as given to bench [default: the "
                   "folders' only method with a confidence].")
@click.option("--check", "check_dirs", multiple=True, type=_existing_folder(),
              help="Bench results of other data (e.g. cross-dataset) to check the calibration "
                   "fitted on all RESULTS against.")
@click.option("--model", "model_path", type=_existing_file(), default=None,
              help="A model file to calibrate (written to -o, never in place).")
@click.option("-o", "--output", type=_file(), default=None,
              help="The calibrated model file to write (with --model).")
@click.option("--out", "out_dir", type=_folder(), default=None,
              help="Folder for confidence.md, confidence.json and confidence.png.")
@force_option
def calibrate(results: tuple[Path, ...], method_spec: str | None, check_dirs: tuple[Path, ...],
              model_path: Path | None, output: Path | None, out_dir: Path | None,
              force: bool) -> None:
    """Check and calibrate a method's predicted per-frame error on bench RESULTS folders.

    RESULTS are `imuloco bench --out` folders of a protocol that tests motion the model never
    saw (heldout-contents: each content's frames are predicted by a calibration fitted on the
    other contents). Prints the per-content table before and after; --check applies the
    calibration of all RESULTS to other folders; --model/-o writes it into a model file.
    """
    # heavy (numpy, the methods): on use, so that --help stays fast
    from imuloco.lab import confidence as conf
    from imuloco.lab.bench import slug
    from imuloco.methods import load_model
    from imuloco.methods.base import calibrated_error

    if (model_path is None) != (output is None):
        raise click.UsageError("--model and -o go together: -o is the calibrated copy")
    check_outputs([output, *(() if out_dir is None else (
        out_dir / n for n in ("confidence.md", "confidence.json", "confidence.png")))],
        force, inputs=[model_path] if model_path else [])
    method = slug(method_spec) if method_spec else None
    rows = conf.load_rows(results, method)
    source = ", ".join(str(r) for r in results)
    calibration = conf.fit(rows, f"out-of-fold results in {source}")
    crossed = conf.crossfit(rows)
    tables = {"uncalibrated": conf.check(rows),
              "calibrated on the other contents": conf.check(rows, crossed)}
    for d in check_dirs:
        other = conf.load_rows([d], method)
        scores = {n: other[f"score_{n}"] for n in conf.score_names(other)}
        missing = sorted(set(calibration["scores"]) - set(scores))
        if missing:
            raise click.UsageError(f"{d}: its rows have no score {missing}, which the "
                                   f"calibration of RESULTS maps (scores {sorted(scores)})")
        predicted = calibrated_error(calibration, scores)
        tables[f"{d}: uncalibrated"] = conf.check(other)
        tables[f"{d}: calibrated on all of RESULTS"] = conf.check(other, predicted)
        if "actual_retargeted_m" in other:  # cross-dataset: also against the truth on the rig
            tables[f"{d}: calibrated on all of RESULTS, against the truth retargeted onto the "
                   "training skeleton"] = conf.check(other, predicted,
                                                     actual="actual_retargeted_m")
    text = "".join(f"\n{title}\n\n{conf.markdown(t)}" for title, t in tables.items())
    click.echo(f"calibration: {calibration}")
    click.echo(text)
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
        with atomic_write(out_dir / "confidence.md", "w") as f:
            f.write(f"# Predicted against actual error\n\ncalibration: "
                    f"`{json.dumps(calibration)}`\n{text}")
        with atomic_write(out_dir / "confidence.json", "w") as f:
            f.write(json.dumps({"calibration": calibration, "tables": tables}, indent=1) + "\n")
        conf.plot(rows, {"uncalibrated": rows["error_m"], "calibrated (other contents)": crossed},
                  out_dir / "confidence.png")
    if model_path is not None:
        model = load_model(model_path)
        model.set_calibration(calibration)
        model.save(output, overwrite=True)  # checked above
        click.echo(f"wrote {output} ({model_path} with this calibration)")


@cli.command()
@click.argument("motion_file", type=_existing_file())
@placement_option
@noise_option
@click.option("--rate", default=100.0, show_default=True,
              type=_Range(MIN_RATE, MAX_RATE),
              help="Sampling rate, Hz (as reconstruct reads logs).")
@click.option("--seed", default=0, show_default=True, type=click.IntRange(min=0),
              help="Seed of the noise draws.")
@click.option("-o", "--output", required=True, type=click.Path(path_type=Path),
              help="CSV file to write (generic format: time_s, acc m/s^2, gyro rad/s); a "
                   "folder for --layout sensorlogger or files.")
@click.option("--layout", type=click.Choice(["generic", "sensorlogger", "files"]),
              default="generic", show_default=True,
              help="generic: one CSV; sensorlogger: an iPhone's Sensor Logger export folder, "
                   "with the watch's WristMotion.csv for left_wrist; files: one generic CSV "
                   "per sensor, PLACEMENT.csv (for reconstruct --sensor).")
@click.option("--stomp", is_flag=True,
              help="Stand still 2 s and stomp twice before the motion (the start that aligns "
                   "sensors' clocks; after the last sensor's clock started).")
@click.option("--clock-offset", "clock_offsets", multiple=True, metavar="PLACEMENT=SECONDS",
              help="--layout files: that sensor's clock runs this far behind (repeatable).")
@force_option
def simulate(motion_file: Path, placement: str, noise: str, rate: float, seed: int,
             output: Path, layout: str, stomp: bool, clock_offsets: tuple[str, ...],
             force: bool) -> None:
    """Simulate body-worn phone sensors on MOTION_FILE and write them as generic CSV (or a
    Sensor Logger export, or one file per sensor)."""
    # heavy (numpy, scipy): on use, so that --help stays fast
    from imuloco.io.motionfile import read_motion
    from imuloco.io.sensorlog import write_generic_csv
    from imuloco.io.sensorwrite import write_sensor_files, write_sensor_logger
    from imuloco.sensors import simulate as sim
    from imuloco.sensors.placement import get_placement

    places = _csv(placement)
    for p in places:
        get_placement(p)  # an unknown preset is refused before reading anything
    offsets = {}
    for item in clock_offsets:
        name, _sep, value = item.partition("=")
        try:
            offsets[name.strip()] = float(value)
        except ValueError:
            raise click.BadParameter(f"{item!r}: expected PLACEMENT=SECONDS",
                                     param_hint="--clock-offset") from None
    if offsets and layout != "files":
        raise click.UsageError("--clock-offset writes one file per sensor: add --layout files")
    if layout == "generic":
        check_output(output, force, inputs=[motion_file])
    motion = read_motion(motion_file)
    stomps: tuple[float, ...] = ()
    if stomp:  # after the last device started: its clock runs the most behind
        late = max([0.0, *offsets.values()])
        motion = sim.still_start(motion, sim.STOMP_LEAD_S + late)
        stomps = tuple(late + t for t in sim.STOMP_AT_S)
    rec = sim.simulate(motion, places, rate=rate, noise=noise, seed=seed, stomps=stomps)
    if layout == "sensorlogger":
        write_sensor_logger(rec, output, overwrite=force)
    elif layout == "files":
        write_sensor_files(rec, output, offsets, overwrite=force)
    else:
        write_generic_csv(rec, output, overwrite=True)
    click.echo(f"wrote {output}: {rec.num_samples} samples, {len(places)} sensor(s) "
               f"({', '.join(places)}), {rec.times[-1] - rec.times[0]:.2f} s, noise {noise}")


@cli.command()
@click.argument("recording", nargs=-1, required=True,
                type=click.Path(exists=True, path_type=Path))
@model_options
@log_options
@click.option("-o", "--output", type=_file(), required=True,
              help="Motion file to write, by its suffix: .bvh, .glb or .gltf (glTF 2.0, "
                   "metres; needs the [gltf] extra); on --rig, or --skeleton's rig.")
@click.option("--video", type=_file(), default=None,
              help="Also render a stick-figure video (.mp4 or .gif).")
@click.option("--video-seconds", type=_Range(0, min_open=True), default=None,
              help="Render only the first seconds into --video.")
@click.option("--html", "html_path", type=_file(), default=None,
              help="Also write the interactive HTML viewer.")
@click.option("--report", "report_path", type=_file(), default=None,
              help="Also write the report (gait, checks) as JSON (a .json file), and beside it "
                   "NAME.md, a readable summary with plots (NAME-*.png; plots need the [viz] "
                   "extra).")
@click.option("--summary", "summary_path", type=_file(), default=None,
              help="Write the readable summary here instead of beside --report (.md).")
@skeleton_option
@rig_option
@calibrate_option
@platform_option
@columns_option
@sensor_option
@click.option("--piece-seconds", type=_ZeroOrRange(10.0), default=None,
              help="Reconstruct in pieces of this many seconds and write the BVH piece by piece "
                   "(bounded memory for long recordings; not with --video/--html/--skeleton/"
                   "--sensor). Default: pieces of 120 s past 5 min of recording, where those "
                   "options allow; 0: always one piece.")
@height_option
@no_fallback_option
@force_option
@_units_option
def reconstruct(recording: tuple[Path, ...], model_path: Path | None, method_name: str | None,
                placement: str, fmt: str, output: Path, video: Path | None,
                video_seconds: float | None, html_path: Path | None,
                report_path: Path | None, summary_path: Path | None, skeleton: Path | None,
                rig: str | None, no_calibrate: bool, platform: str | None,
                columns: dict[str, str] | None, sensors: list[tuple[str, Path]],
                piece_seconds: float | None, height: float | None, no_fallback: bool,
                force: bool, units: str) -> None:
    """Reconstruct full-body motion from a phone RECORDING and write it as BVH or glTF.

    RECORDING is a sensor log (CSV; see imuloco.io.sensorlog), a Sensor Logger folder, or an
    accelerometer file and a gyroscope file, in either order (a RealWorld acc_*.csv finds its
    gyroscope_*.csv).
    """
    # heavy (the app, the methods, torch): on use, so that --help stays fast
    from imuloco.app.chunked import plan_pieces, reconstruct_to_bvh
    from imuloco.app.export import check_motion_output, check_report_output
    from imuloco.app.outputs import Outputs, write_outputs
    from imuloco.app.pipeline import reconstruct_file
    from imuloco.app.summary import summary_paths, write_summary

    if video is not None and video.suffix.lower() not in (".mp4", ".gif"):  # before any work
        raise click.BadParameter(f"{video}: expected a .mp4 or .gif file", param_hint="--video")
    if summary_path is None and report_path is not None and report_path.suffix == ".json":
        summary_path = report_path.with_suffix(".md")  # (another suffix is refused below)
    summaries = [] if summary_path is None else list(summary_paths(summary_path).values())
    inputs = [*recording, *(f for _, f in sensors), *([model_path] if model_path else []),
              *([skeleton] if skeleton else [])]
    check_outputs([output, video, html_path, report_path, *summaries], force, inputs=inputs)
    check_motion_output(output, "-o/--output")
    if report_path is not None:
        check_report_output(report_path)
    outputs = Outputs(output, report_path, video, html_path, video_seconds, units,
                      _preset(rig, skeleton))
    source = recording[0] if len(recording) == 1 else list(recording)
    whole = next((name for name, given in [("--video", video), ("--html", html_path),
                                           ("--skeleton", skeleton),
                                           ("a glTF -o", output.suffix.lower() != ".bvh")]
                  if given), None)
    if piece_seconds:
        if sensors:
            raise click.UsageError("--piece-seconds reads one log: drop --sensor")
        if whole:
            raise click.UsageError("--piece-seconds writes a BVH on a --rig preset only: "
                                   "drop --video/--html/--skeleton, write a .bvh")
    piece_seconds, imported = plan_pieces(source, piece_seconds, whole, sensors,
                                          placement=placement, fmt=fmt, platform=platform,
                                          columns=columns)
    if piece_seconds is not None:
        pieces = reconstruct_to_bvh(source, output, method_name, model_path, placement, fmt,
                                    not no_calibrate, platform=platform, overwrite=True,
                                    piece_s=piece_seconds, progress=True, unit=units,
                                    height=height, rig=outputs.rig, columns=columns,
                                    fallback=not no_fallback, imported=imported)
        written = write_outputs(outputs, pieces)  # the report: the BVH is written
        if summary_path:
            written.append(write_summary(pieces.to_json(), summary_path, overwrite=True)[0])
        m, c = pieces.motion, pieces["confidence"]
        click.echo(f"{m.frames} frames at {m.fps:g} fps ({m.duration_s:.1f} s) in "
                   f"{pieces.pieces.count} piece(s)" + _confidence_text(c) + "; wrote "
                   + ", ".join(str(p) for p in written))
        _echo_gait_source(pieces.gait_source, pieces.gait_note)
        return
    motion, report = reconstruct_file(source, model=model_path, method=method_name,
                                      placement=placement, fmt=fmt, calibrate=not no_calibrate,
                                      progress=True, platform=platform, skeleton=skeleton,
                                      height=height, columns=columns, sensors=sensors,
                                      fallback=not no_fallback, imported=imported)
    click.echo(f"model: {report.model}", err=True)
    written = write_outputs(outputs, report, motion, progress=True)
    if summary_path:
        written.append(write_summary(report.to_json(), summary_path, overwrite=True,
                                     name=motion.name)[0])
    g = report.gait.to_json()
    rhythm = (report.motion_gait or report.gait).to_json()["cadence_rhythm_spm"]  # the legs'
    click.echo(f"{motion.num_frames} frames at {motion.fps:g} fps ({motion.duration:.1f} s); "
               f"cadence {_num(rhythm, 1)} steps/min from the legs' rhythm "
               f"(raw signal: {_num(report.signal_cadence_spm, 1)}), "
               f"{_num(g['cadence_spm'], 1)} from {int(g['steps'] or 0)} steps; "
               f"speed {_num(g['speed_mps'], 2)} m/s"
               + _confidence_text(report["confidence"]))
    if report.signal_swing_deg is not None:  # a shank sensor: how far its leg should swing
        p = report.plausibility.to_json()
        click.echo(f"shank swing a stride: right {_num(p['right_shank_swing_deg'], 0)} deg, "
                   f"left {_num(p['left_shank_swing_deg'], 0)} "
                   f"(raw signal: {_num(report.signal_swing_deg, 0)})")
    _echo_gait_source(report.gait_source, report.gait_note)
    click.echo("wrote " + ", ".join(str(p) for p in written))


def _preset(rig: str | None, skeleton: Path | None) -> str | None:
    """The rig preset to write with: ``rig``, by default ``bvh-default``; None with
    ``--skeleton`` (the motion is retargeted onto the user's rig), which excludes ``--rig``."""
    from imuloco.core.rigs import DEFAULT_RIG  # heavy (numpy, scipy): on use

    if rig is not None and skeleton is not None:
        raise click.UsageError("--rig and --skeleton are exclusive: --skeleton retargets onto "
                               "your rig (its names and rest pose), --rig writes a preset")
    return None if skeleton is not None else rig or DEFAULT_RIG


def _echo_gait_source(source: str, note: str | None) -> None:
    """Say where the gait came from when it is not the reconstructed motion (a foot or
    lower-back sensor's own signal), and the report's note on it (e.g. no --height)."""
    if not source.startswith("the reconstructed motion"):
        click.echo(f"gait: {source}")
    if note:
        click.echo(f"gait note: {note}")


def _confidence_text(c: dict) -> str:
    """'; predicted error ..., N % of frames flagged unreliable' from a report's
    ``confidence``, what of it the method gives (empty for none)."""
    mean = c.get("mean_error_m")
    text = "" if mean is None else f"predicted error {100 * mean:.1f} cm (mean rms over joints)"
    text = (text + _flagged_text(c)).removeprefix(", ")
    return f"; {text}" if text else ""


def _flagged_text(c: dict) -> str:
    """', N % of frames flagged unreliable' from a report's ``confidence`` (or empty)."""
    frac = c.get("unreliable_fraction")
    return "" if frac is None else f", {100 * frac:.1f} % of frames flagged unreliable"


@cli.command()
@click.option("--out", "out_dir", type=_folder(), default=Path("imuloco-demo"),
              show_default=True, help="Folder for the outputs.")
@model_options
@skeleton_option
@rig_option
@force_option
@_units_option
def demo(out_dir: Path, model_path: Path | None, method_name: str | None,
         skeleton: Path | None, rig: str | None, force: bool, units: str) -> None:
    """Simulate a phone on the right ankle of a bundled walk, reconstruct it and write the
    BVH, a side-by-side video (MP4, GIF), the HTML viewer, plots and a report."""
    from imuloco.app.pipeline import demo as run_demo  # heavy: on use

    report = run_demo(out_dir, method=method_name, model=model_path, overwrite=force,
                      progress=True, unit=units, skeleton=skeleton,
                      preset=_preset(rig, skeleton))
    m = report["metrics"]
    click.echo(f"model: {report['model']}")
    g, gt = report["gait"], report["gait_ground_truth"]
    click.echo(f"MPJPE {_num(m['mpjpe_cm'], 1)} cm, joint angle error "
               f"{_num(m['angle_deg'], 1)} deg; cadence {_num(g['cadence_rhythm_spm'], 1)} "
               f"steps/min from the legs' rhythm, {_num(g['cadence_spm'], 1)} from detected "
               f"strikes (ground truth {_num(gt['cadence_spm'], 1)}); "
               f"{report['seconds']:.0f} s")
    check = report["confidence_check"]
    if check["mean_predicted_error_m"] is not None:
        click.echo(f"predicted error {100 * check['mean_predicted_error_m']:.1f} cm per frame "
                   f"(mean rms over joints), actual {100 * check['mean_actual_error_m']:.1f} "
                   "cm" + _flagged_text(report["confidence"]))
    click.echo(f"wrote {len(report['files'])} files to {out_dir}/ (open demo.html or "
               f"demo.mp4; report.md)")


RENDER_TYPES = (".mp4", ".gif", ".html", ".png")


@cli.command()
@click.argument("motion_file", metavar="MOTION", type=_existing_file())
@click.option("--ground-truth", "gt_file", type=_existing_file(), default=None,
              help="A ground-truth motion drawn on the left, side by side.")
@click.option("--out", "out_dir", type=_folder(), default=None,
              help="Folder for MOTION.mp4, MOTION.gif and MOTION.html (video, GIF and viewer).")
@click.option("-o", "--output", "outputs", multiple=True, type=_file(),
              help="File(s) to write: .mp4, .gif, .html or .png (a strip of frames).")
@click.option("--start", type=_Range(min=0), default=None, metavar="SECONDS",
              help="Videos and frame strip from this time on [default: the start].")
@click.option("--end", type=_Range(min=0), default=None, metavar="SECONDS",
              help="Videos and frame strip up to this time [default: the end].")
@click.option("--seconds", type=_Range(0, min_open=True), default=None,
              help="At most this many seconds from --start (videos, frame strip).")
@click.option("--gif/--no-gif", default=True, show_default=True,
              help="With --out: MOTION.gif too, a preview of at most 30 s (an MP4 has no "
                   "cap; a longer window's GIF is cut, with a message).")
@click.option("--report", "report_file", type=_existing_file(), default=None,
              help="MOTION's reconstruction report (reconstruct --report, batch's NAME.json): "
                   "the videos and viewer show its predicted error and unreliable segments.")
@force_option
def render(motion_file: Path, gt_file: Path | None, out_dir: Path | None,
           outputs: tuple[Path, ...], start: float | None, end: float | None,
           seconds: float | None, gif: bool, report_file: Path | None, force: bool) -> None:
    """Render a MOTION file (BVH, ...) as stick-figure video, HTML viewer or frame strip:
    into a folder (--out DIR) and/or to named files (-o FILE, repeatable). Videos are
    streamed to the encoder frame by frame (memory does not grow with the recording);
    --start/--end render a window of a long one."""
    # heavy (numpy, matplotlib, the app): on use, so that --help stays fast
    import numpy as np

    from imuloco.app.confidence import Confidence
    from imuloco.app.render import render_outputs
    from imuloco.io.motionfile import read_motion
    from imuloco.viz.skeleton import frame_strip, frame_window

    if out_dir is None and not outputs:
        raise click.UsageError("give --out DIR or -o FILE")
    outputs = (*outputs, *(out_dir / f"{motion_file.stem}{ext}" for ext in RENDER_TYPES[:3]
                           if out_dir is not None and (gif or ext != ".gif")))
    bad = [str(p) for p in outputs if p.suffix.lower() not in RENDER_TYPES]
    if bad:
        raise click.BadParameter(f"unsupported output type(s) {bad}: use .mp4, .gif, .html "
                                 "or .png", param_hint="--output")
    check_outputs(outputs, force, inputs=[motion_file, *([gt_file] if gt_file else []),
                                          *([report_file] if report_file else [])])
    motion = read_motion(motion_file)
    motions, titles = [motion], [motion.name or motion_file.stem]
    confidence = [None]
    if report_file is not None:
        confidence = [Confidence.from_report(report_file, motion.num_frames, motion.fps)]
    if gt_file is not None:
        motions, titles = [read_motion(gt_file), motion], ["ground truth", titles[0]]
        confidence = [None, *confidence]
    first, stop = frame_window(motions[0], start, end, seconds)  # refused before any work
    videos = [p for p in outputs if p.suffix.lower() in (".mp4", ".gif")]
    html = next((p for p in outputs if p.suffix.lower() == ".html"), None)
    written = render_outputs(motions, titles, videos, html, overwrite=True, progress=True,
                             max_seconds=seconds, confidence=confidence, start=start,
                             end=end)
    for p in outputs:
        if p.suffix.lower() == ".png":
            times = np.linspace(first, stop - 1, 8) / motions[0].fps
            written.append(frame_strip(motions, times, p, titles, overwrite=True))
    click.echo("wrote " + ", ".join(str(p) for p in written))


@cli.command()
@click.argument("recordings", nargs=-1, type=click.Path(exists=True, path_type=Path))
@click.option("--glob", "patterns", multiple=True, metavar="PATTERN",
              help="Recordings matching a glob pattern, e.g. 'logs/*.csv' (repeatable); the "
                   "files of a Sensor Logger or phyphox export are its folder, one walker.")
@click.option("--out", "out_dir", type=_folder(), required=True,
              help="Folder for NAME.bvh, NAME.json, summary.csv/.json, walkers.parquet and "
                   "strides.parquet.")
@click.option("-j", "--jobs", type=click.IntRange(min=1), default=None,
              help="Dask worker processes of the local cluster [default: one per CPU].")
@click.option("--scheduler", metavar="ADDRESS", default=None,
              help="Run on an existing Dask cluster, e.g. tcp://host:8786 (see the README).")
@model_options
@log_options
@calibrate_option
@platform_option
@skeleton_option
@rig_option
@height_option
@click.option("--walkers", "walkers_file", type=_existing_file(), default=None, metavar="CSV",
              help="Each walker's height: a CSV with a header and the columns name (the "
                   "recording's output NAME, as in NAME.bvh) and height_m (metres; empty or "
                   "no row: --height); its other columns are carried into summary.csv and "
                   "walkers.parquet. One file can hold the whole study: rows without a "
                   "recording here are counted, not refused, unless close to a recording "
                   "without a row (a typo).")
@columns_option
@click.option("--force", is_flag=True,
              help="Redo recordings whose outputs are complete (a re-run skips them).")
@click.option("--timeout", type=_Range(0, min_open=True), default=None, metavar="SECONDS",
              help="A recording with no result after this long is an error row (a stuck "
                   "input) [default: 3600].")
@_units_option
def batch(recordings: tuple[Path, ...], patterns: tuple[str, ...], out_dir: Path,
          jobs: int | None, scheduler: str | None, model_path: Path | None,
          method_name: str | None, placement: str, fmt: str, skeleton: Path | None,
          rig: str | None, no_calibrate: bool, platform: str | None, height: float | None,
          walkers_file: Path | None, columns: dict[str, str] | None, force: bool,
          timeout: float | None, units: str) -> None:
    """Reconstruct many RECORDINGS (one walker each) on Dask: a BVH and a gait report per
    recording, summary.csv, walkers.parquet and strides.parquet; resumable (a re-run skips
    finished recordings, redoes walkers whose height changed).

    A recording's NAME is its file name without extension (acc_X for a RealWorld pair, the
    folder's or zip's name for a Sensor Logger or phyphox export), with its folder's name
    prepended where names repeat (also in case alone) or where it is 'summary'."""
    from imuloco.app.batch import TIMEOUT_S, find_recordings, run_batch  # heavy: on use

    paths = find_recordings(recordings, patterns, out_dir=out_dir)
    if not paths:
        raise click.UsageError("no recordings: give files or --glob PATTERN")
    summary = run_batch(paths, out_dir, jobs, model_path, method_name, placement, fmt,
                        calibrate=not no_calibrate, force=force, progress=True,
                        scheduler=scheduler, platform=platform, unit=units,
                        skeleton=skeleton, height_m=height, walkers=walkers_file,
                        timeout_s=TIMEOUT_S if timeout is None else timeout,
                        rig=_preset(rig, skeleton), columns=columns)
    click.echo(f"model: {summary['model']}", err=True)
    click.echo(f"{'name':<28} {'cadence':>8} {'speed':>6} {'step':>6}  status")
    for r in summary["recordings"]:
        click.echo(f"{r['name'][:28]:<28} {_num(r['cadence_spm'], 1):>8} "
                   f"{_num(r['speed_mps'], 2):>6} {_num(r['step_length_m'], 2):>6}  "
                   f"{r['status'] if r['status'] == 'ok' else r['error']}")
    rate = summary["done"] / max(summary["seconds"], 1e-9) * 60
    click.echo(f"{summary['done']} done, {summary['skipped']} skipped, {summary['failed']} "
               f"failed of {len(paths)} in {summary['seconds']:.1f} s ({rate:.1f} "
               f"recordings/min on {summary['jobs']} worker(s)); wrote {out_dir}/summary.csv, "
               "walkers.parquet and strides.parquet")
    if summary["failed"]:
        raise click.ClickException(f"{summary['failed']} recording(s) failed; see "
                                   f"{out_dir / 'summary.csv'}")


@cli.command()
@click.option("--host", default="127.0.0.1", show_default=True,
              help="Interface to listen on (0.0.0.0 lets a phone on the network connect).")
@click.option("--port", default=8765, show_default=True, type=click.IntRange(0, 65535))
@model_options
@log_options
@click.option("--calibrate-seconds", default=5.0, show_default=True,
              type=_Range(MIN_CALIBRATE_S, MAX_CALIBRATE_S),
              help="Seconds of samples to calibrate the phone on the leg (0: none).")
@click.option("--replay", type=click.Path(exists=True, path_type=Path), default=None,
              help="Stream this recorded log (of --format) at real time instead of waiting "
                   "for a phone.")
@click.option("--speed", type=_Range(0, min_open=True), default=1.0, show_default=True,
              help="Replay speed factor.")
@click.option("--loop", is_flag=True, help="Replay the recording over and over.")
@click.option("--cert", "certfile", type=click.Path(exists=True, dir_okay=False), default=None,
              help="TLS certificate (PEM): serve HTTPS, which phones need for motion sensors.")
@click.option("--key", "keyfile", type=click.Path(exists=True, dir_okay=False), default=None,
              help="Private key of --cert.")
@click.option("--https", "self_signed", is_flag=True,
              help="Serve HTTPS with a certificate made for this session (self-signed: the "
                   "phone asks once to accept it); instead of --cert/--key.")
@click.option("--allow-origin", "allow_origins", multiple=True, metavar="ORIGIN",
              help="Also accept browsers on this origin (https://host:port); repeatable.")
@click.option("--vmc", "vmc", metavar="HOST[:PORT]", default=None,
              help="Also send every pose over the VMC protocol (OSC/UDP; port 39539 by "
                   "default) to VSeeFace, VMC4B (Blender), EVMC4U (Unity), ...")
@height_option
@no_fallback_option
def live(host: str, port: int, model_path: Path | None, method_name: str | None,
         placement: str, calibrate_seconds: float, replay: Path | None, fmt: str, speed: float,
         loop: bool, certfile: str | None, keyfile: str | None, self_signed: bool,
         allow_origins: tuple[str, ...], vmc: str | None, height: float | None,
         no_fallback: bool) -> None:
    """Watch a walker live: a phone on the leg streams its sensors (open /phone on it), a
    browser shows the reconstruction as it walks (open /live); --vmc also sends it to a VMC
    protocol receiver (Unity HumanBodyBones, T-pose rest). Ctrl-C stops."""
    import asyncio  # on use, so that --help stays fast (as below)

    try:  # the [live] extra
        from imuloco.app.live import lan
        from imuloco.app.live.server import LiveServer, configure_logging, run, ssl_context
        if vmc is not None:
            from imuloco.app.live.vmc import parse_address
    except ModuleNotFoundError as e:
        if e.name not in ("websockets", "segno", "psutil", "cryptography", "pythonosc"):
            raise
        raise MissingExtraError("live mode", e.name, "live") from None
    from imuloco.app.pipeline import choose_model  # heavy: on use

    if self_signed and certfile:
        raise click.UsageError("--https makes its own certificate: drop --cert/--key")
    vmc_to = None if vmc is None else parse_address(vmc)  # before the model loads
    choice = choose_model(method_name, model_path, placement, progress=True)
    server = LiveServer(choice.method, calibrate_seconds, choice.description,
                        allow_origins=allow_origins, height_m=height, vmc=vmc_to,
                        fallback=not no_fallback)
    shown = lan.shown_host(host)
    with tempfile.TemporaryDirectory(prefix="imuloco-live-") as tmp:  # the session's key
        if self_signed:
            certfile, keyfile = map(str, lan.self_signed([shown, "localhost", "127.0.0.1"],
                                                         tmp))
        ssl = ssl_context(certfile, keyfile) if certfile else None

        def started(srv: LiveServer) -> None:
            click.echo(f"model: {choice}", err=True)
            if srv.vmc is not None:
                click.echo(f"vmc:    sending poses to {srv.vmc.host}:{srv.vmc.port} (OSC/UDP)",
                           err=True)
            urls = srv.urls(shown)
            click.echo(f"viewer: {urls['live']}\nphone:  {urls['phone']}" +
                       ("" if host != "127.0.0.1" else "  (--host 0.0.0.0 for a phone on the "
                                                       "network)"))
            if host == "127.0.0.1":
                return
            if shown == "localhost":
                click.echo("no network address found on this machine: is it on Wi-Fi?",
                           err=True)
            click.echo("scan with the phone (on the same network):\n"
                       + lan.qr_text(urls["phone"]))
            if self_signed:
                click.echo(f"https: {lan.PHONE_WARNING}", err=True)
            elif not ssl:
                click.echo("phones only give motion sensors to https pages: add --https (or "
                           "--cert and --key)", err=True)

        configure_logging()
        replay_args = None if replay is None else {"path": replay, "placement": placement,
                                                   "fmt": fmt, "speed": speed, "loop": loop}
        try:
            asyncio.run(run(server, host, port, ssl, replay_args, on_start=started))
        except KeyboardInterrupt:
            click.echo("stopped")


def main() -> None:
    cli()


if __name__ == "__main__":
    main()
