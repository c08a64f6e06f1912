"""The ``imuloco`` command line: parses arguments and calls library functions.

Each command is a thin wrapper; the work lives in the library so that tests call it too.
"""

from __future__ import annotations

import json
from pathlib import Path

import click


@click.group()
@click.version_option(package_name="imuloco")
def cli() -> None:
    """Full-body locomotion reconstruction from one body-worn inertial sensor."""


@cli.command()
@click.argument("file", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--json", "as_json", is_flag=True, help="Print JSON instead of text.")
def info(file: Path, as_json: bool) -> None:
    """Joints, frames, fps, duration and the body map found for a motion FILE."""
    from imuloco.core.bodymap import PARTS
    from imuloco.io.motionfile import read_motion

    motion = read_motion(file)
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


def main() -> None:
    cli()


if __name__ == "__main__":
    main()
