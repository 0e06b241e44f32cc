#!/usr/bin/env bash
# The Python package (crates/python): a virtual environment under the
# target folder with pinned maturin, pytest, NumPy and onnx; the extension
# built by maturin as an abi3 wheel and installed; then its pytest suite
# (crates/python/tests), which also runs examples/python/train_until_verified.py.
#
# The wheel is built under cargo's `dev` profile into the same target folder
# as `cargo test`: the dependencies (faer, Clarabel, nalgebra, …) are
# compiled with the same settings there (opt-level 2, the workspace's
# `profile.dev.package."*"`), so after `cargo test` (scripts/test.sh) only
# the workspace's crates and PyO3 are compiled, in about a minute; the
# workspace's crates at opt-level 0 run the suite in seconds. (The `test`
# profile itself cannot build a cdylib: it makes every target a test
# harness. A wheel for use is built with `maturin build --release`.)
#
# Needs python3 (3.9 or later) with pip. Where `python3 -m venv` cannot
# make an environment (Debian's python3 without the python3-venv package),
# the package is installed with apt-get when this runs as root or with sudo.
set -euo pipefail
cd "$(dirname "$0")/.."
target="${CARGO_TARGET_DIR:-$PWD/target}"
venv="$target/python-venv"
python="${PYTHON:-python3}"

if [ ! -x "$venv/bin/python" ]; then
    rm -rf "$venv"
    if ! "$python" -m venv "$venv" >/dev/null 2>&1; then
        rm -rf "$venv"
        echo "test-python: '$python -m venv' failed; installing python3-venv" >&2
        SUDO=""
        if [ "$(id -u)" != 0 ]; then SUDO="sudo"; fi
        $SUDO apt-get update -qq
        DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq python3-venv >/dev/null
        "$python" -m venv "$venv"
    fi
fi
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check \
    maturin==1.9.6 pytest==8.4.2 numpy==2.3.5 onnx==1.19.1

# the extension is not a default member, so CI's `cargo clippy` does not
# see it: lint it here, as strictly (PyO3's build configuration depends on
# the environment maturin sets, so a second run compiles PyO3 again for
# each: about 70 s, where a run without the lint takes 10)
PYO3_PYTHON="$venv/bin/python" cargo clippy -p ravel-python --all-targets -- -D warnings

wheels="$target/python-wheels"
rm -rf "$wheels"
"$venv/bin/maturin" build --profile dev --manifest-path crates/python/Cargo.toml \
    --interpreter "$venv/bin/python" --out "$wheels"
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check \
    --force-reinstall --no-deps "$wheels"/ravel-*.whl

# the command line `cargo test` built, for the test comparing the reports
export RAVEL_BIN="$target/debug/ravel"
"$venv/bin/python" -m pytest crates/python/tests -q
