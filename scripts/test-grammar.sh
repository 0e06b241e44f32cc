#!/usr/bin/env bash
# Check the VS Code extension's TextMate grammar
# (editors/vscode/syntaxes/ravel.tmLanguage.json) against the annotated
# samples editors/vscode/test/*.ravel-test, with vscode-tmgrammar-test from
# npm, installed at the version of the committed lock file into
# target/grammar-test (never into the repository); checks that the
# extension's script parses; then scripts/test-extension.sh packages the
# extension with vsce (from the same lock file) and starts the `ravel lsp`
# it launches (it needs the ravel binary: run cargo build first). Needs
# node and npm.
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
work="$root/target/grammar-test"

if ! command -v npm >/dev/null 2>&1; then
    echo "test-grammar: npm is not installed (apt-get install nodejs npm)" >&2
    exit 2
fi

mkdir -p "$work"
cp "$root/editors/vscode/test/package.json" "$root/editors/vscode/test/package-lock.json" "$work/"
cd "$work"
# install unless this very lock file is already installed
if ! cmp -s package-lock.json node_modules/.installed-lock.json 2>/dev/null; then
    npm ci --no-audit --no-fund --ignore-scripts --loglevel=error
    cp package-lock.json node_modules/.installed-lock.json
fi

# the extension's script at least parses (it runs only inside VS Code)
node --check "$root/editors/vscode/extension.js"

# run from $work (its package.json names no grammar), so the grammar tested
# is exactly the one given with -g
node_modules/.bin/vscode-tmgrammar-test \
    -g "$root/editors/vscode/syntaxes/ravel.tmLanguage.json" \
    "$root/editors/vscode/test/*.ravel-test"

# the extension packaged and its launch of `ravel lsp` (the binary of
# $CARGO_TARGET_DIR or target/, or the one given as this script's argument)
bash "$root/scripts/test-extension.sh" "$work" "$@"
