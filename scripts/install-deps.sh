#!/usr/bin/env bash
# Installs the one system library ravel needs: OpenBLAS/LAPACK, which the SDP
# back-end (clarabel's `sdp` feature) links against, with Debian's
# single-threaded build beside it (build.rs links that one statically: the
# threaded build's idle workers spin on a core at start-up, and loading the
# shared library costs every process start a millisecond and a half).
# Idempotent; does nothing when both are already installed.
set -euo pipefail
have_dev=no
if [ -e /usr/lib/x86_64-linux-gnu/libopenblas.so ] || [ -e /usr/lib/aarch64-linux-gnu/libopenblas.so ] \
   || ldconfig -p 2>/dev/null | grep -q 'libopenblas\.so '; then
    have_dev=yes
fi
have_serial=no
if ls /usr/lib/*-linux-gnu/openblas-serial/libopenblas.a >/dev/null 2>&1; then
    have_serial=yes
fi
if [ "$have_dev" = yes ] && [ "$have_serial" = yes ]; then
    exit 0
fi
SUDO=""
if [ "$(id -u)" != 0 ]; then SUDO="sudo"; fi
$SUDO apt-get update -qq
# shellcheck disable=SC2086
DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq libopenblas-dev libopenblas-serial-dev >/dev/null
