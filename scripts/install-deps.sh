#!/usr/bin/env bash
# Installs the one system library ravel needs: OpenBLAS/LAPACK, which the SDP
# back-end (clarabel's `sdp` feature) calls; crates/analysis/src/blas.rs opens
# libopenblas.so.0 on the first SDP solve. The -dev package brings the
# threaded build (safe to call from several threads, which --jobs needs).
# Idempotent; does nothing when the library is already installed.
set -euo pipefail
if [ -e /usr/lib/x86_64-linux-gnu/libopenblas.so ] || [ -e /usr/lib/aarch64-linux-gnu/libopenblas.so ] \
   || ldconfig -p 2>/dev/null | grep -q 'libopenblas\.so '; then
    exit 0
fi
SUDO=""
if [ "$(id -u)" != 0 ]; then SUDO="sudo"; fi
$SUDO apt-get update -qq
DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq libopenblas-dev >/dev/null
