#!/usr/bin/env bash
# Install Debian's INDI server and command-line clients (package indi-bin: indiserver,
# indi_getprop, indi_setprop, indi_eval) for the INDI driver `vs-indi` and its tests.
# Idempotent and quick when indiserver is already on PATH.
set -euo pipefail

if command -v indiserver >/dev/null 2>&1; then
    echo "indiserver already installed: $(command -v indiserver)"
    exit 0
fi
if ! command -v apt-get >/dev/null 2>&1; then
    echo "setup/40-indi.sh: apt-get not found; install indi-bin (indiserver) by hand, or the" \
         "INDI tests will be skipped" >&2
    exit 0
fi
SUDO=""
if [ "$(id -u)" -ne 0 ]; then
    if command -v sudo >/dev/null 2>&1; then SUDO="sudo"; else
        echo "setup/40-indi.sh: not root and no sudo; install the indi-bin package by hand" >&2
        exit 0
    fi
fi
install() {
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q --no-install-recommends indi-bin
}
if ! install; then
    echo "setup/40-indi.sh: install failed; refreshing package lists once and retrying"
    $SUDO apt-get update -q
    install
fi
command -v indiserver >/dev/null 2>&1 && echo "indiserver installed: $(command -v indiserver)"
