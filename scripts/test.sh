#!/usr/bin/env bash
# The whole test suite, what CI runs (README's second set-up command):
# the system library the SDP solver opens, then every Rust test, then the
# checks outside cargo: the VS Code extension's grammar against its
# annotated samples, the extension packaged and its launch of `ravel lsp`
# (node and npm), the HTML report in a browser, and the Python package (a
# wheel built by maturin, its pytest suite).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
cargo test
bash scripts/test-grammar.sh
# the HTML report in headless Chromium (installed when missing), with the
# binary `cargo test` built
bash scripts/test-report.sh
# the Python package: its wheel (maturin) and its pytest suite
bash scripts/test-python.sh
