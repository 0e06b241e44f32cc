#!/usr/bin/env bash
# The VS Code extension (editors/vscode) as far as it can be checked without
# VS Code: packaged into a .vsix with `vsce package` (its runtime dependency,
# vscode-languageclient, installed from the extension's lock file), the
# package holding the manifest, the script, the language configuration, the
# grammar and the client library but not test/; then
# editors/vscode/test/launch.js checks what package.json contributes and
# runs extension.js with stand-ins for VS Code's modules, starting the
# `ravel lsp` it launches and talking to it over JSON-RPC.
#
# Usage: scripts/test-extension.sh TOOLS [RAVEL_BINARY]
#   TOOLS: the folder where scripts/test-grammar.sh installed the tools of
#   editors/vscode/test/package-lock.json (it runs this script with it);
#   RAVEL_BINARY: default $CARGO_TARGET_DIR/debug/ravel or target/debug/ravel.
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
tools="${1:?usage: scripts/test-extension.sh TOOLS [RAVEL_BINARY]}"
bin="${2:-${CARGO_TARGET_DIR:-$root/target}/debug/ravel}"
if [ ! -x "$bin" ]; then
    echo "test-extension: no ravel binary at $bin (run cargo build first)" >&2
    exit 2
fi
bin="$(cd "$(dirname "$bin")" && pwd)/$(basename "$bin")"
tools="$(cd "$tools" && pwd)"
if [ ! -x "$tools/node_modules/.bin/vsce" ]; then
    echo "test-extension: no vsce under $tools (scripts/test-grammar.sh installs it)" >&2
    exit 2
fi

# a copy of the extension (never a node_modules folder in the repository)
work="$root/target/extension-test"
rm -rf "$work/ext"
mkdir -p "$work/ext"
cp -r "$root/editors/vscode/." "$work/ext/"
cd "$work/ext"
npm ci --omit=dev --no-audit --no-fund --ignore-scripts --loglevel=error

vsce="$tools/node_modules/.bin/vsce"
files="$("$vsce" ls)"
for f in package.json extension.js language-configuration.json \
    syntaxes/ravel.tmLanguage.json node_modules/vscode-languageclient/node.js; do
    if ! grep -qx "$f" <<<"$files"; then
        echo "test-extension: the package would not hold $f" >&2
        exit 1
    fi
done
if grep -q '^test/' <<<"$files"; then
    echo "test-extension: the package would hold test/ (see .vscodeignore)" >&2
    exit 1
fi
"$vsce" package --allow-missing-repository --skip-license -o "$work/ravel.vsix" >/dev/null
if [ "$(head -c 2 "$work/ravel.vsix")" != "PK" ]; then
    echo "test-extension: $work/ravel.vsix is not a package" >&2
    exit 1
fi
echo "test-extension: packaged $work/ravel.vsix ($(wc -c <"$work/ravel.vsix") bytes)"

node "$root/editors/vscode/test/launch.js" "$work/ext" "$bin"
