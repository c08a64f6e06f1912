"""The ``imuloco`` command line: parses arguments and calls library functions.

Each command is a thin wrapper; the work lives in the library so that tests call it too.
"""

from __future__ import annotations

import json
from pathlib import Path

import click

from imuloco.errors import ImulocoError


class Commands(click.Group):
    """The command group: an :class:`~imuloco.errors.ImulocoError` raised by any command ends
    it with ``Error: <message>`` and exit status 1, instead of a traceback."""

    def invoke(self, ctx: click.Context):
        try:
            return super().invoke(ctx)
        except ImulocoError as e:
            raise click.ClickException(str(e)) from None


@click.group(cls=Commands)
@click.version_option(package_name="imuloco")
def cli() -> None:
    """Full-body locomotion reconstruction from one body-worn inertial sensor."""


_height_option = click.option(
    "--height", type=click.FloatRange(0.5, 2.6), default=None, metavar="METRES",
    help="The wearer's body height: the skeleton and every length and speed in their "
         "proportions [default: the training skeleton's].")


def _reading_options(f):
    """``--up`` and ``--skip-frames``: how motion files are read (``read_bvh``'s options)."""
    f = click.option("--skip-frames", type=click.IntRange(min=0), default=0, show_default=True,
                     help="Drop this many leading frames of each motion file (a prepended "
                          "T-pose).")(f)
    return click.option("--up", type=click.Choice(["auto", "y", "z"]), default="auto",
                        show_default=True,
                        help="Vertical axis of the motion files; Z-up files are turned Y up "
                             "(auto: detected from the animated body).")(f)


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
    from imuloco.core.bodymap import PARTS
    from imuloco.io.motionfile import read_motion

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
    """List the reconstruction methods with one line each."""
    from imuloco.methods import available_methods

    found = available_methods()
    width = max(len(n) for n in found)
    for name, cls in found.items():
        online = "online" if cls.supports_online else "offline"
        click.echo(f"{name:<{width}}  [{online:>7}]  {cls.summary}")


def _csv(value: str | None) -> list[str]:
    return [v.strip() for v in (value or "").split(",") if v.strip()]


def _folders(values: tuple[str, ...]) -> list[Path] | None:
    """Folders given as a repeatable and/or comma separated option; each must exist."""
    folders = [Path(v) for item in values for v in _csv(item)]
    for f in folders:
        if not f.is_dir():
            raise click.BadParameter(f"folder {f} does not exist", param_hint="--data")
    return folders or None


DATA_HELP = ("Folder(s) of clips, repeatable or comma separated; several become one set on "
             "the first one's skeleton and frame rate (others retargeted) [default: the "
             "bundled sample].")


@cli.command()
@click.option("--method", "method_names", default=None,
              help="Method name(s), comma separated (see `imuloco methods`); a variant as "
                   "NAME[key=value;key=value], e.g. eom2014[variant=mlp-no-hmm] [required "
                   "but with --batch, which defaults to the shipped model].")
@click.option("--split", "split_name",
              type=click.Choice(["random-clips", "heldout-styles", "heldout-contents",
                                 "cross-dataset"]),
              default="random-clips", show_default=True,
              help="Protocol (imuloco.evaluate.protocols); cross-dataset takes --train/--test.")
@click.option("--noise", type=click.Choice(["clean", "phone", "imu"]), default="phone",
              show_default=True)
@click.option("--placement", default="right_ankle", show_default=True,
              help="Sensor placement preset(s), comma separated.")
@click.option("--data", "data_items", multiple=True, help=DATA_HELP)
@click.option("--train", "train_items", multiple=True,
              help="cross-dataset: training folder(s), repeatable or comma separated.")
@click.option("--test", "test_items", multiple=True, help="cross-dataset: the test folder.")
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), required=True,
              help="Folder for results.json and results.md.")
@click.option("--limit", type=int, default=None,
              help="Read at most N clips per folder (quick runs).")
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--seeds", "n_seeds", type=click.IntRange(min=1), default=1, show_default=True,
              help="Train each method with N seeds (seed, seed+1, ...): mean and spread.")
@click.option("--speed", is_flag=True,
              help="Run the speed benchmark (imuloco.evaluate.speed) instead.")
@click.option("--db-frames", default=None,
              help="With --speed: database sizes in frames, comma separated.")
@click.option("--fuzz", type=click.IntRange(1), default=None, metavar="N",
              help="Instead: read N generated malformed inputs per reader (imuloco.evaluate."
                   "fuzz) and write fuzz.md and fuzz.json.")
@click.option("--readers", default=None,
              help="With --fuzz: readers, comma separated [default: all].")
@click.option("--real", "real_dir", type=click.Path(exists=True, file_okay=False, path_type=Path),
              default=None, help="Instead: the real-data gait protocol on this folder (real "
                                 "IMUs with references, imuloco.evaluate.real).")
@click.option("--baseline", is_flag=True,
              help="With --real: also measure a right-ankle reconstruction's gait.")
@click.option("--batch", "batch_walkers", type=click.IntRange(1), default=None, metavar="N",
              help="Instead: the batch benchmark (imuloco.evaluate.batchbench) on N simulated "
                   "walkers of 60 s; writes batch_bench.md and batch_bench.json.")
@click.option("--load", "load_dirs", multiple=True, metavar="DIR",
              type=click.Path(exists=True, file_okay=False, path_type=Path),
              help="Instead: time loading these motion folders (repeat or comma-separate): "
                   "numpy parse, reader, cold and warm cache; writes load.json and load.md.")
@click.option("--against", default=None, metavar="REV",
              help="With --load: also time the BVH reader of this git commit.")
@_reading_options
def bench(method_names: str | None, split_name: str, noise: str, placement: str,
          data_items: tuple[str, ...], train_items: tuple[str, ...],
          test_items: tuple[str, ...], out: Path, limit: int | None, seed: int, n_seeds: int,
          speed: bool, db_frames: str | None, fuzz: int | None, readers: str | None,
          batch_walkers: int | None, load_dirs: tuple[Path, ...], against: str | None,
          real_dir: Path | None, baseline: bool, up: str, skip_frames: int) -> None:
    """Train methods, reconstruct every test clip and write results.json and results.md."""
    if fuzz is not None:
        from imuloco.evaluate.fuzz import READERS, write_fuzz

        chosen = tuple(_csv(readers)) or READERS
        unknown = sorted(set(chosen) - set(READERS))
        if unknown:
            raise click.BadParameter(f"unknown reader(s) {unknown}; expected {list(READERS)}",
                                     param_hint="--readers")
        click.echo(write_fuzz(fuzz, out, chosen, seed=seed, progress=True))
        return
    if real_dir is not None:
        from imuloco.evaluate.real import run_real, summarize, table

        rows = run_real(real_dir, out, limit, baseline, progress=True)
        click.echo(table(summarize(rows)))
        click.echo(f"wrote {out / 'real.json'}, real.csv and README.md")
        return
    if batch_walkers is not None:
        from imuloco.evaluate.batchbench import batch_benchmark, markdown

        click.echo(markdown(batch_benchmark(batch_walkers, out, method=method_names,
                                            placement=placement)))
        click.echo(f"wrote {out / 'batch_bench.json'} and {out / 'batch_bench.md'}")
        return
    if load_dirs:
        from imuloco.evaluate.loadspeed import load_benchmark, table

        folders = [Path(p) for d in load_dirs for p in _csv(str(d))]
        click.echo(table(load_benchmark(folders, out, against), against))
        click.echo(f"wrote {out / 'load.json'} and {out / 'load.md'}")
        return
    if not method_names:
        raise click.UsageError("Missing option '--method' (or pass --fuzz N, --batch N, "
                               "--load DIR or --real DIR).")
    names = _csv(method_names)
    data = _folders(data_items)
    if speed:
        from imuloco.evaluate.speed import speed_benchmark

        frames = [int(v) for v in _csv(db_frames)] or None
        speed_benchmark(names, out, data[0] if data else None, frames)
        return
    from imuloco.evaluate.bench import run_bench
    from imuloco.evaluate.report import COLUMNS, table

    try:
        records = run_bench(names, split_name, noise, _csv(placement), data, out, limit, seed,
                            progress=True, seeds=n_seeds, train=_folders(train_items),
                            test=_folders(test_items), up=up, skip_frames=skip_frames)
    except KeyError as e:
        raise click.UsageError(str(e.args[0])) from None
    click.echo(table([r for r in records if r["motion_type"] == "all"], COLUMNS))
    click.echo(f"wrote {out / 'results.json'} and {out / 'results.md'}")


@cli.command()
@click.argument("ground_truth", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.argument("reconstructed", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--json", "as_json", is_flag=True, help="Print JSON instead of text.")
def evaluate(ground_truth: Path, reconstructed: Path, as_json: bool) -> None:
    """Print the metrics of a RECONSTRUCTED motion against its GROUND_TRUTH (same skeleton;
    the longer is cut to the shorter's length)."""
    from imuloco.evaluate.metrics import evaluate_files

    try:
        values, note = evaluate_files(ground_truth, reconstructed)
    except ValueError as e:
        raise click.ClickException(str(e)) from None
    if note:
        click.echo(note, err=True)
    if as_json:
        click.echo(json.dumps(values, indent=2))
        return
    for key, value in values.items():
        click.echo(f"{key:>20}: {value:.4g}")


def _param(items: tuple[str, ...]) -> dict:
    """``key=value`` pairs; values parsed as JSON when they can be (numbers, true, null)."""
    out = {}
    for item in items:
        if "=" not in item:
            raise click.BadParameter(f"expected key=value, got {item!r}", param_hint="--param")
        key, value = item.split("=", 1)
        try:
            out[key.strip()] = json.loads(value)
        except json.JSONDecodeError:
            out[key.strip()] = value
    return out


@cli.command()
@click.option("--method", "method_name", required=True, help="Method name (`imuloco methods`).")
@click.option("--data", "data_items", multiple=True, help=DATA_HELP)
@click.option("--placement", default="right_ankle", show_default=True,
              help="Sensor placement preset(s), comma separated.")
@click.option("--noise", type=click.Choice(["clean", "phone", "imu"]), default="phone",
              show_default=True)
@click.option("--split", "split_name", type=click.Choice(["random-clips", "heldout-styles"]),
              default=None, help="Train on this split's training part only [default: all].")
@click.option("--param", "params", multiple=True, metavar="KEY=VALUE",
              help="A hyperparameter of the method (repeatable), e.g. --param epochs=4.")
@click.option("--limit", type=int, default=None, help="Read at most N clips (quick runs).")
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path), required=True,
              help="Model file to write (.npz).")
@click.option("--force", is_flag=True, help="Overwrite the output file.")
@_reading_options
def train(method_name: str, data_items: tuple[str, ...], placement: str, noise: str,
          split_name: str | None, params: tuple[str, ...], limit: int | None, seed: int,
          output: Path, force: bool, up: str, skip_frames: int) -> None:
    """Fit a method on motion clips with simulated sensors and save the model.

    Writes OUTPUT, and for methods that keep a training history (``learned``) its losses per
    epoch beside it as OUTPUT.history.json and, with matplotlib, OUTPUT.curves.png.
    """

    from imuloco.evaluate.bench import data_label, load_data
    from imuloco.evaluate.protocols import split
    from imuloco.methods import get_method

    if output.exists() and not force:
        raise click.UsageError(f"{output} exists; pass --force to replace it")
    try:
        method = get_method(method_name, **_param(params))
    except KeyError as e:
        raise click.UsageError(str(e.args[0])) from None
    except TypeError as e:
        raise click.UsageError(f"--param: {e}") from None
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
    method.save(output, overwrite=force)
    click.echo(f"trained {method_name} on {len(db)} clips ({db.num_frames} frames) in "
               f"{seconds / 60:.1f} min; wrote {output}")
    for path in method.write_training_report(output):
        click.echo(f"wrote {path}")


@cli.command("export-onnx")
@click.option("--model", "model_path", type=click.Path(exists=True, dir_okay=False,
                                                       path_type=Path), required=True,
              help="A model file written by `imuloco train` (method learned).")
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path), required=True,
              help="ONNX file to write.")
@click.option("--force", is_flag=True, help="Overwrite the output file.")
def export_onnx_command(model_path: Path, output: Path, force: bool) -> None:
    """Export a learned model to ONNX (per-frame network with its recurrent state)."""
    from imuloco.methods import load_model

    model = load_model(model_path)
    if model.name != "learned":
        raise click.UsageError(f"{model_path}: method {model.name!r} has no ONNX export; "
                               "only `learned` models do")
    from imuloco.methods.learned.export import export_onnx

    try:
        path = export_onnx(model, output, overwrite=force)
    except FileExistsError as e:
        raise click.UsageError(str(e)) from None
    click.echo(f"wrote {path}")


@cli.command()
@click.argument("motion_file", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--placement", default="right_ankle", show_default=True,
              help="Sensor placement(s), comma separated (e.g. right_ankle,pelvis).")
@click.option("--noise", default="phone", show_default=True,
              help="Noise preset: clean, phone or imu.")
@click.option("--rate", default=100.0, show_default=True, type=click.FloatRange(1.0, 10_000.0),
              help="Sampling rate, Hz.")
@click.option("--seed", default=0, show_default=True, type=int, help="Seed of the noise draws.")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="CSV file to write (generic format: time_s, acc m/s^2, gyro rad/s).")
@click.option("--force", is_flag=True, help="Replace OUTPUT if it exists.")
def simulate(motion_file: Path, placement: str, noise: str, rate: float, seed: int,
             output: Path, force: bool) -> None:
    """Simulate body-worn phone sensors on MOTION_FILE and write them as generic CSV."""
    from imuloco.io.motionfile import read_motion
    from imuloco.io.sensorlog import write_generic_csv
    from imuloco.sensors.noise import NOISE_PRESETS
    from imuloco.sensors.placement import PRESETS
    from imuloco.sensors.simulate import simulate as simulate_sensors

    places = _csv(placement)
    unknown = [p for p in places if p not in PRESETS]
    if unknown:
        raise click.BadParameter(f"unknown placement(s) {unknown}; presets: {sorted(PRESETS)}",
                                 param_hint="--placement")
    if noise not in NOISE_PRESETS:
        raise click.BadParameter(f"unknown noise {noise!r}; presets: {sorted(NOISE_PRESETS)}",
                                 param_hint="--noise")
    from imuloco.io.atomic import check_output

    check_output(output, force, inputs=[motion_file])
    rec = simulate_sensors(read_motion(motion_file), places, rate=rate, noise=noise, seed=seed)
    write_generic_csv(rec, output, overwrite=True)
    click.echo(f"wrote {output}: {rec.num_samples} samples, {len(places)} sensor(s) "
               f"({', '.join(places)}), {rec.times[-1] - rec.times[0]:.2f} s, noise {noise}")


def _refuse_existing(paths: list[Path | None], force: bool) -> None:
    taken = [str(p) for p in paths if p is not None and p.exists()]
    if taken and not force:
        raise click.UsageError(f"{', '.join(taken)} exist(s); pass --force to replace")


@cli.command()
@click.argument("recording", nargs=-1, required=True,
                type=click.Path(exists=True, path_type=Path))
@click.option("--model", "model_path", type=click.Path(exists=True, dir_okay=False,
                                                       path_type=Path), default=None,
              help="Model file from `imuloco train` [default: the shipped pretrained model].")
@click.option("--method", "method_name", default=None,
              help="Method to use without --model (its shipped model, or fitted on the "
                   "bundled sample) [default: learned, else the best available baseline].")
@click.option("--placement", default="right_ankle", show_default=True,
              help="Where the phone was worn (placement preset).")
@click.option("--format", "fmt", default="auto", show_default=True,
              type=click.Choice(["auto", "generic", "realworld", "phyphox", "sensorlogger"]),
              help="Sensor log format.")
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path), required=True,
              help="BVH file to write (on the model's training skeleton, or --skeleton's).")
@click.option("--video", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Also render a stick-figure video (.mp4 or .gif).")
@click.option("--video-seconds", type=float, default=None,
              help="Render only the first seconds into --video.")
@click.option("--html", "html_path", type=click.Path(dir_okay=False, path_type=Path),
              default=None, help="Also write the interactive HTML viewer.")
@click.option("--report", "report_path", type=click.Path(dir_okay=False, path_type=Path),
              default=None, help="Also write the report (gait, checks) as JSON.")
@click.option("--skeleton", "skeleton", type=click.Path(exists=True, dir_okay=False,
                                                       path_type=Path), default=None,
              help="A BVH of your rig: the motion is retargeted onto it (its joint names, "
                   "offsets and rest pose) [default: the model's training skeleton].")
@click.option("--no-calibrate", is_flag=True, help="Skip the phone-on-leg calibration.")
@click.option("--platform", type=click.Choice(["ios", "android"]), default=None,
              help="Phone of a Sensor Logger export [default: from its Metadata.csv, else "
                   "guessed with a warning].")
@click.option("--piece-seconds", type=click.FloatRange(10.0), default=None,
              help="Reconstruct in pieces of this many seconds and write the BVH piece by piece "
                   "(bounded memory for long recordings; not with --video/--html).")
@_height_option
@click.option("--force", is_flag=True, help="Replace existing output files.")
@_units_option
def reconstruct(recording: tuple[Path, ...], model_path: Path | None, method_name: str | None,
                placement: str, fmt: str, output: Path, video: Path | None,
                video_seconds: float | None, html_path: Path | None,
                report_path: Path | None, skeleton: Path | None, no_calibrate: bool,
                platform: str | None, piece_seconds: float | None, height: float | None,
                force: bool,
                units: str) -> None:
    """Reconstruct full-body motion from a phone RECORDING and write it as BVH.

    RECORDING is a sensor log (CSV; see imuloco.io.sensorlog), a Sensor Logger folder, or an
    accelerometer file and a gyroscope file (a RealWorld acc_*.csv finds its gyroscope_*.csv).
    """
    from imuloco.app.pipeline import reconstruct_file, render_outputs
    from imuloco.errors import FormatError
    from imuloco.io.atomic import atomic_write, check_output
    from imuloco.io.bvh import write_bvh

    _refuse_existing([output, video, html_path, report_path], force)
    for out in (output, video, html_path, report_path):
        if out is not None:
            check_output(out, force=True, inputs=[*recording, *([skeleton] if skeleton else [])])
    source = recording[0] if len(recording) == 1 else list(recording)
    if piece_seconds is not None:
        if video or html_path or skeleton or height is not None:
            raise click.UsageError("--piece-seconds writes the BVH on the model's skeleton "
                                   "only: drop --video/--html/--skeleton/--height")
        from imuloco.app.chunked import reconstruct_to_bvh

        report = reconstruct_to_bvh(source, output, method_name, model_path, placement, fmt,
                                    not no_calibrate, platform=platform, overwrite=force,
                                    piece_s=piece_seconds, progress=True, unit=units)
        if report_path:
            with atomic_write(report_path, "w") as f:
                f.write(json.dumps(report, indent=2) + "\n")
        m = report["motion"]
        click.echo(f"{m['frames']} frames at {m['fps']:g} fps ({m['duration_s']:.1f} s) in "
                   f"{report['pieces']['count']} piece(s); wrote "
                   + ", ".join(str(p) for p in (output, report_path) if p))
        return
    try:
        motion, report = reconstruct_file(source, model=model_path, method=method_name,
                                          placement=placement, fmt=fmt,
                                          calibrate=not no_calibrate, progress=True,
                                          platform=platform, skeleton=skeleton, height=height)
    except (FormatError, KeyError, ValueError) as e:
        raise click.ClickException(str(e.args[0] if isinstance(e, KeyError) else e)) from None
    click.echo(f"model: {report['model']}", err=True)
    write_bvh(motion, output, unit=units, overwrite=force)
    written = [output]
    if video or html_path:
        written += render_outputs([motion], [f"{motion.name} ({report['method']})"],
                                  [video] if video else [], html_path, overwrite=force,
                                  progress=True, max_seconds=video_seconds)
    if report_path:
        with atomic_write(report_path, "w") as f:
            f.write(json.dumps(report, indent=2) + "\n")
        written.append(report_path)
    g = report["gait"]
    click.echo(f"{motion.num_frames} frames at {motion.fps:g} fps ({motion.duration:.1f} s); "
               f"cadence {g['cadence_rhythm_spm']} steps/min from the legs' rhythm (raw "
               f"signal: {report['signal_cadence_spm']}), {g['cadence_spm']} from "
               f"{int(g['steps'] or 0)} detected strikes; speed {g['speed_mps']} m/s")
    click.echo("wrote " + ", ".join(str(p) for p in written))


@cli.command()
@click.option("--out", "out_dir", type=click.Path(file_okay=False, path_type=Path),
              default=Path("imuloco-demo"), show_default=True, help="Folder for the outputs.")
@click.option("--method", "method_name", default=None,
              help="Method to use [default: learned, else the best available baseline].")
@click.option("--model", "model_path", type=click.Path(exists=True, dir_okay=False,
                                                       path_type=Path), default=None,
              help="Model file from `imuloco train`.")
@click.option("--skeleton", "skeleton", type=click.Path(exists=True, dir_okay=False,
                                                       path_type=Path), default=None,
              help="A BVH of your rig: the motion is retargeted onto it (its joint names, "
                   "offsets and rest pose) [default: the model's training skeleton].")
@click.option("--force", is_flag=True, help="Replace existing output files.")
@_units_option
def demo(out_dir: Path, method_name: str | None, model_path: Path | None,
         skeleton: Path | None, force: bool, units: str) -> None:
    """Simulate a phone on the right ankle of a bundled walk, reconstruct it and write the
    BVH, a side-by-side video (MP4, GIF), the HTML viewer, plots and a report."""
    from imuloco.app.pipeline import demo as run_demo

    try:
        report = run_demo(out_dir, method=method_name, model=model_path, overwrite=force,
                          progress=True, unit=units, skeleton=skeleton)
    except (FileExistsError, KeyError) as e:
        raise click.UsageError(str(e.args[0] if isinstance(e, KeyError) else e)) from None
    m = report["metrics"]
    click.echo(f"model: {report['model']}")
    g, gt = report["gait"], report["gait_ground_truth"]
    click.echo(f"MPJPE {m['mpjpe_cm']:.1f} cm, joint angle error {m['angle_deg']:.1f} deg; "
               f"cadence {g['cadence_rhythm_spm']:.1f} steps/min from the legs' rhythm, "
               f"{g['cadence_spm']:.1f} from detected strikes "
               f"(ground truth {gt['cadence_spm']:.1f}); "
               f"{report['seconds']:.0f} s")
    click.echo(f"wrote {len(report['files'])} files to {out_dir}/ (open demo.html or "
               f"demo.mp4; report.md)")


@cli.command()
@click.argument("motion_file", metavar="MOTION", type=click.Path(exists=True, dir_okay=False,
                                                                 path_type=Path))
@click.option("--ground-truth", "gt_file", type=click.Path(exists=True, dir_okay=False,
                                                           path_type=Path), default=None,
              help="A ground-truth motion drawn on the left, side by side.")
@click.option("-o", "--output", "outputs", multiple=True, required=True,
              type=click.Path(dir_okay=False, path_type=Path),
              help="File(s) to write: .mp4, .gif, .html or .png (a strip of frames).")
@click.option("--seconds", type=float, default=None, help="Only the first seconds (videos).")
@click.option("--force", is_flag=True, help="Replace existing output files.")
def render(motion_file: Path, gt_file: Path | None, outputs: tuple[Path, ...],
           seconds: float | None, force: bool) -> None:
    """Render a MOTION file (BVH, ...) as stick-figure video, HTML viewer or frame strip."""
    import numpy as np

    from imuloco.app.pipeline import render_outputs
    from imuloco.io.motionfile import read_motion
    from imuloco.viz.skeleton import frame_strip

    bad = [str(p) for p in outputs if p.suffix.lower() not in (".mp4", ".gif", ".html", ".png")]
    if bad:
        raise click.BadParameter(f"unsupported output type(s) {bad}: use .mp4, .gif, .html "
                                 "or .png", param_hint="--output")
    _refuse_existing(list(outputs), force)
    motion = read_motion(motion_file)
    motions, titles = [motion], [motion.name or motion_file.stem]
    if gt_file is not None:
        motions, titles = [read_motion(gt_file), motion], ["ground truth", titles[0]]
    videos = [p for p in outputs if p.suffix.lower() in (".mp4", ".gif")]
    html = next((p for p in outputs if p.suffix.lower() == ".html"), None)
    written = render_outputs(motions, titles, videos, html, overwrite=force, progress=True,
                             max_seconds=seconds)
    for p in outputs:
        if p.suffix.lower() == ".png":
            span = motion.duration if seconds is None else min(seconds, motion.duration)
            written.append(frame_strip(motions, np.linspace(0, span, 8), p, titles,
                                       overwrite=force))
    click.echo("wrote " + ", ".join(str(p) for p in written))


@cli.command()
@click.argument("recordings", nargs=-1, type=click.Path(exists=True, path_type=Path))
@click.option("--glob", "patterns", multiple=True, metavar="PATTERN",
              help="Recordings matching a glob pattern, e.g. 'logs/*.csv' (repeatable).")
@click.option("--out", "out_dir", type=click.Path(file_okay=False, path_type=Path),
              required=True, help="Folder for NAME.bvh, NAME.json, summary.csv/.json, "
              "walkers.parquet and strides.parquet.")
@click.option("-j", "--jobs", type=int, default=None,
              help="Dask worker processes of the local cluster [default: one per CPU].")
@click.option("--scheduler", metavar="ADDRESS", default=None,
              help="Run on an existing Dask cluster, e.g. tcp://host:8786 (see the README).")
@click.option("--model", "model_path", type=click.Path(exists=True, dir_okay=False,
                                                       path_type=Path), default=None,
              help="Model file from `imuloco train` [default: the shipped pretrained model].")
@click.option("--method", "method_name", default=None,
              help="Method to use without --model [default: learned, else a baseline].")
@click.option("--placement", default="right_ankle", show_default=True,
              help="Where the phones were worn (placement preset).")
@click.option("--format", "fmt", default="auto", show_default=True,
              type=click.Choice(["auto", "generic", "realworld", "phyphox", "sensorlogger"]),
              help="Sensor log format.")
@click.option("--skeleton", "skeleton", type=click.Path(exists=True, dir_okay=False,
                                                       path_type=Path), default=None,
              help="A BVH of your rig: the motion is retargeted onto it (its joint names, "
                   "offsets and rest pose) [default: the model's training skeleton].")
@click.option("--no-calibrate", is_flag=True, help="Skip the phone-on-leg calibration.")
@click.option("--platform", type=click.Choice(["ios", "android"]), default=None,
              help="Phone of Sensor Logger exports [default: from their Metadata.csv, else "
                   "guessed with a warning].")
@_height_option
@click.option("--force", is_flag=True,
              help="Redo recordings whose outputs are complete (a re-run skips them).")
@_units_option
def batch(recordings: tuple[Path, ...], patterns: tuple[str, ...], out_dir: Path,
          jobs: int | None, scheduler: str | None, model_path: Path | None,
          method_name: str | None, placement: str, fmt: str, skeleton: Path | None,
          no_calibrate: bool, platform: str | None, height: float | None, force: bool,
          units: str) -> None:
    """Reconstruct many RECORDINGS (one walker each) on Dask: a BVH and a gait report per
    recording, summary.csv, walkers.parquet and strides.parquet; resumable (a re-run skips
    finished recordings)."""
    from imuloco.app.batch import find_recordings, run_batch

    paths = find_recordings(recordings, patterns)
    if not paths:
        raise click.UsageError("no recordings: give files or --glob PATTERN")
    try:
        summary = run_batch(paths, out_dir, jobs, model_path, method_name, placement, fmt,
                            calibrate=not no_calibrate, force=force, progress=True,
                            scheduler=scheduler, platform=platform, unit=units,
                            skeleton=skeleton, height_m=height)
    except (KeyError, ValueError) as e:
        raise click.UsageError(str(e.args[0] if isinstance(e, KeyError) else e)) from None
    click.echo(f"model: {summary['model']}", err=True)
    click.echo(f"{'name':<28} {'cadence':>8} {'speed':>6} {'step':>6}  status")
    def fmt_v(v: float | None, digits: int) -> str:
        return "–" if v is None else f"{v:.{digits}f}"

    for r in summary["recordings"]:
        click.echo(f"{r['name'][:28]:<28} {fmt_v(r['cadence_spm'], 1):>8} "
                   f"{fmt_v(r['speed_mps'], 2):>6} {fmt_v(r['step_length_m'], 2):>6}  "
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
@click.option("--port", default=8765, show_default=True, type=int)
@click.option("--model", "model_path", type=click.Path(exists=True, dir_okay=False,
                                                       path_type=Path), default=None,
              help="Model file from `imuloco train` (an online method).")
@click.option("--method", "method_name", default=None,
              help="Online method to use without --model [default: learned, else a baseline].")
@click.option("--placement", default="right_ankle", show_default=True,
              help="Where the phone is worn (placement preset).")
@click.option("--calibrate-seconds", type=float, default=5.0, show_default=True,
              help="Seconds of samples to calibrate the phone on the leg (0: none).")
@click.option("--replay", type=click.Path(exists=True, path_type=Path), default=None,
              help="Stream this recorded log at real time instead of waiting for a phone.")
@click.option("--format", "fmt", default="auto", show_default=True,
              type=click.Choice(["auto", "generic", "realworld", "phyphox", "sensorlogger"]),
              help="Format of the --replay log.")
@click.option("--speed", type=float, default=1.0, show_default=True,
              help="Replay speed factor.")
@click.option("--loop", is_flag=True, help="Replay the recording over and over.")
@click.option("--cert", "certfile", type=click.Path(exists=True, dir_okay=False), default=None,
              help="TLS certificate (PEM): serve HTTPS, which phones need for motion sensors.")
@click.option("--key", "keyfile", type=click.Path(exists=True, dir_okay=False), default=None,
              help="Private key of --cert.")
@click.option("--allow-origin", "allow_origins", multiple=True, metavar="ORIGIN",
              help="Also accept browsers on this origin (https://host:port); repeatable.")
def live(host: str, port: int, model_path: Path | None, method_name: str | None,
         placement: str, calibrate_seconds: float, replay: Path | None, fmt: str, speed: float,
         loop: bool, certfile: str | None, keyfile: str | None,
         allow_origins: tuple[str, ...]) -> None:
    """Watch a walker live: a phone on the leg streams its sensors (open /phone on it), a
    browser shows the reconstruction as it walks (open /live). Ctrl-C stops."""
    import asyncio

    try:
        from imuloco.app.live.server import LiveServer, configure_logging, run, ssl_context
    except ImportError as e:
        raise click.ClickException(f"live mode needs websockets: pip install imuloco[live] "
                                   f"({e})") from None
    from imuloco.app.pipeline import choose_method

    try:
        fitted, note = choose_method(method_name, model_path, placement, progress=True)
        server = LiveServer(fitted, calibrate_seconds, note, allow_origins=allow_origins)
    except (KeyError, ValueError) as e:
        raise click.UsageError(str(e.args[0] if isinstance(e, KeyError) else e)) from None
    ssl = ssl_context(certfile, keyfile) if certfile else None
    shown = "localhost" if host in ("127.0.0.1", "0.0.0.0", "::") else host

    def started(srv: LiveServer) -> None:
        click.echo(f"model: {note}", err=True)
        urls = srv.urls(shown)
        click.echo(f"viewer: {urls['live']}\nphone:  {urls['phone']}" +
                   ("" if host != "127.0.0.1" else "  (--host 0.0.0.0 for a phone on the "
                                                   "network)"))
        if not ssl and host != "127.0.0.1":
            click.echo("phones only give motion sensors to https pages: pass --cert and --key",
                       err=True)

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
