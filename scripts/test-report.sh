#!/usr/bin/env bash
# The HTML report (`ravel verify … --report DIR`) in a real browser:
# installs Debian's `chromium` when it is missing (apt-get, with sudo when
# not root, as install-deps.sh does), writes a report for a few shipped specs
# (closed loops with box, GSG and polytope sets, a falsified one, network
# specs) with the built binary, loads it headless with --dump-dom and checks
# that the page's own check ran: every inline plot has a non-empty box
# (`<body data-rendered="ok N/N">`, set by the report's inline script), one
# table row and one plot per pair.
#
# Usage: scripts/test-report.sh [RAVEL_BINARY]   (default: target/debug/ravel,
# or $CARGO_TARGET_DIR/debug/ravel; build it first with `cargo build`)
set -euo pipefail
cd "$(dirname "$0")/.."
BIN="${1:-${CARGO_TARGET_DIR:-target}/debug/ravel}"
if [ ! -x "$BIN" ]; then
    echo "test-report: no ravel binary at $BIN (run cargo build first)" >&2
    exit 2
fi

CHROMIUM=""
for c in chromium chromium-browser; do
    if command -v "$c" >/dev/null 2>&1; then CHROMIUM="$c"; break; fi
done
if [ -z "$CHROMIUM" ]; then
    start=$(date +%s)
    SUDO=""
    if [ "$(id -u)" != 0 ]; then SUDO="sudo"; fi
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends chromium >/dev/null
    CHROMIUM=chromium
    echo "test-report: installed chromium in $(( $(date +%s) - start )) s"
fi

WORK="$(mktemp -d)"
trap 'rm -rf "$WORK"' EXIT
SPECS=(
    specs/double_integrator.ravel
    specs/double_integrator_falsified.ravel
    specs/double_integrator_hull.ravel
    specs/quadrotor_gsg.ravel
    specs/quadrotor_polytope_boundary.ravel
    specs/network/classifier_falsified.ravel
    specs/network/policy_output_set.ravel
)
# exit 1 (a FALSIFIED spec is among them) is expected; 2 is not
set +e
"$BIN" verify "${SPECS[@]}" --quiet --no-timing --report "$WORK/report" > "$WORK/verify.txt"
code=$?
set -e
if [ "$code" -ne 1 ]; then
    echo "test-report: ravel verify exited $code (expected 1)" >&2
    cat "$WORK/verify.txt" >&2
    exit 1
fi

start=$(date +%s%N)
timeout 120 "$CHROMIUM" --headless --no-sandbox --disable-gpu --disable-quic --no-first-run \
    --disable-background-networking --disable-component-update --disable-sync \
    --user-data-dir="$WORK/profile" \
    --dump-dom "file://$WORK/report/index.html" > "$WORK/dom.html" 2> "$WORK/chromium.log" || {
    echo "test-report: chromium failed" >&2
    tail -20 "$WORK/chromium.log" >&2
    exit 1
}
ms=$(( ($(date +%s%N) - start) / 1000000 ))

n=${#SPECS[@]}
fail=0
if ! grep -q "data-rendered=\"ok $n/$n\"" "$WORK/dom.html"; then
    echo "test-report: the page did not render its $n plots: $(grep -o 'data-rendered="[^"]*"' "$WORK/dom.html" || echo 'no data-rendered (script did not run)')" >&2
    fail=1
fi
rows=$(grep -o '<tr class="pair"' "$WORK/dom.html" | wc -l)
if [ "$rows" -ne "$n" ]; then
    echo "test-report: $rows table rows for $n pairs" >&2
    fail=1
fi
if [ -n "${REPORT_SCREENSHOT:-}" ]; then
    "$CHROMIUM" --headless --no-sandbox --disable-gpu --disable-quic --no-first-run \
        --disable-background-networking --disable-component-update --disable-sync \
        --user-data-dir="$WORK/profile2" --window-size=1400,2000 \
        --screenshot="$REPORT_SCREENSHOT" "file://$WORK/report/index.html" 2>/dev/null
fi
if [ "$fail" -ne 0 ]; then exit 1; fi
echo "test-report: ok ($n pairs, every plot rendered; chromium took $ms ms)"
