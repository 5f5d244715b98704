#!/usr/bin/env bash
# Install Debian's INDI server and command-line clients (package indi-bin: indiserver,
# indi_getprop, indi_setprop, indi_eval) for the INDI driver `vs-indi` and its tests.
# Idempotent and quick when indiserver is already on PATH.
set -euo pipefail
. "$(dirname "$0")/lib/apt.bash"

if command -v indiserver >/dev/null 2>&1; then
    echo "indiserver already installed: $(command -v indiserver)"
    exit 0
fi
need_apt setup/40-indi.sh indi-bin "the INDI tests will be skipped"
apt_install setup/40-indi.sh indi-bin
command -v indiserver >/dev/null 2>&1 && echo "indiserver installed: $(command -v indiserver)"
