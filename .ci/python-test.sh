#!/usr/bin/env bash
# The Python package's tests: a fresh virtual environment, maturin, numpy and pytest from PyPI,
# `pip install ./crates/symframe-py` (maturin builds the extension as the PEP 517 backend), then
# pytest, which compares the package's results with the `symframe` binary's.
set -euo pipefail
cd "$(dirname "$0")/.."
if ! command -v python3 >/dev/null; then
    echo "python-test: python3 not found; skipping the Python package's tests"
    exit 0
fi
venv="${SYMFRAME_PY_VENV:-target/py-venv}"
rm -rf "$venv"
python3 -m venv "$venv"
# The build backend runs the `maturin` command of this environment.
export PATH="$PWD/$venv/bin:$PATH"
"$venv/bin/pip" install --quiet --upgrade pip
"$venv/bin/pip" install --quiet "maturin>=1,<2" numpy pytest
# The binary the tests compare with: $SYMFRAME where set (.ci/run gives the one `cargo test`
# built), else the debug build.
if [ -n "${SYMFRAME:-}" ]; then
    SYMFRAME_BIN="$(realpath "$SYMFRAME")"
else
    cargo build --locked --quiet -p symframe-cli
    SYMFRAME_BIN="$PWD/target/debug/symframe"
fi
export SYMFRAME_BIN
# --no-build-isolation: maturin from the venv above, no second download. The dev profile (optimised
# in this workspace) reuses what `cargo test` built instead of a second, release build.
MATURIN_PEP517_ARGS="--profile dev" "$venv/bin/pip" install --quiet --no-build-isolation ./crates/symframe-py
# Run from the tests' folder so that the installed package, not the source tree, is imported.
cd crates/symframe-py/tests
"../../../$venv/bin/python" -m pytest -q -p no:cacheprovider .
