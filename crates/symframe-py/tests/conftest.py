"""Shared fixtures: a small synthetic capture and the command-line binary to compare with."""

import os
import shutil
import subprocess
from pathlib import Path

import pytest

import symframe

REPO = Path(__file__).resolve().parents[3]


def cli_binary():
    """The `symframe` command: $SYMFRAME_BIN, else a build in the workspace's target folder."""
    env = os.environ.get("SYMFRAME_BIN")
    if env:
        return env
    for profile in ("release", "debug"):
        p = REPO / "target" / profile / "symframe"
        if p.is_file():
            return str(p)
    return shutil.which("symframe")


@pytest.fixture(scope="session")
def cli():
    """Runs the command line; returns the completed process."""
    binary = cli_binary()
    if binary is None:
        pytest.skip("no symframe binary: build it (cargo build) or set SYMFRAME_BIN")

    def run(*args, check=True):
        return subprocess.run([binary, *map(str, args)], capture_output=True, text=True, check=check)

    return run


@pytest.fixture(scope="session")
def capture(tmp_path_factory):
    """A 40 x 40 brushed-metal sphere under 150 lights, as an .lp dataset folder."""
    root = tmp_path_factory.mktemp("capture")
    lp = symframe.synth(root / "sphere", size=40, lights=150)
    return Path(lp)
