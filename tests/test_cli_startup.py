"""The command line starts without the heavy stack: importing :mod:`imuloco.cli` and building
every command's ``--help`` loads no numpy, scipy, torch, scikit-learn, matplotlib nor any
method (what made ``reconstruct --help`` take seconds, issue #43). Times are measured by
``benchmarks/startup.py``, not here; this checks what is imported."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

HEAVY = ("numpy", "scipy", "torch", "sklearn", "matplotlib", "pandas", "pyarrow", "dask")
LIGHT_METHODS = {"imuloco.methods", "imuloco.methods.registry", "imuloco.methods.names"}

ALL_HELP = """
import json, sys
import click
from imuloco.cli import cli

def helps(command, ctx):
    command.get_help(ctx)
    names = [ctx.command_path]
    if isinstance(command, click.Group):
        for name, sub in command.commands.items():
            names += helps(sub, click.Context(sub, info_name=name, parent=ctx))
    return names

shown = helps(cli, click.Context(cli, info_name="imuloco"))
print(json.dumps({"commands": shown, "modules": sorted(sys.modules)}))
"""


@pytest.fixture(scope="module")
def fresh_help() -> dict:
    """Every command's help built in a fresh interpreter: the commands and the modules it
    loaded."""
    done = subprocess.run([sys.executable, "-c", ALL_HELP], capture_output=True, text=True,
                          check=True)
    return json.loads(done.stdout)


def test_every_help_is_built_without_the_heavy_stack(fresh_help):
    commands = set(fresh_help["commands"])
    assert {"imuloco reconstruct", "imuloco batch", "imuloco live", "imuloco simulate",
            "imuloco bench run", "imuloco bench speed"} <= commands  # the help of each
    modules = fresh_help["modules"]
    loaded = sorted(m for m in modules if m.split(".")[0] in HEAVY)
    assert not loaded, loaded
    methods = sorted(m for m in modules if m.startswith("imuloco.methods") and
                     m not in LIGHT_METHODS)
    assert not methods, methods  # the method stack
    assert not [m for m in modules if m.startswith(("imuloco.lab", "imuloco.app.pipeline"))]
