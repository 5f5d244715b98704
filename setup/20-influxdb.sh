#!/usr/bin/env bash
# Install InfluxDB 1.x (Debian's `influxdb` package) for the recorder's server store and its tests.
# Idempotent and quick when `influxd` is already on PATH. The system service is neither
# enabled nor started: the tests and users start `influxd` themselves with their own config.
set -euo pipefail

if command -v influxd >/dev/null 2>&1; then
    echo "influxd already installed: $(command -v influxd)"
    exit 0
fi

if ! command -v apt-get >/dev/null 2>&1; then
    echo "setup/20-influxdb.sh: apt-get not found; install InfluxDB 1.x (influxd) by hand," \
         "or the InfluxDB tests will be skipped" >&2
    exit 0
fi

SUDO=""
if [ "$(id -u)" -ne 0 ]; then
    if command -v sudo >/dev/null 2>&1; then SUDO="sudo"; else
        echo "setup/20-influxdb.sh: not root and no sudo; install the influxdb package by hand" >&2
        exit 0
    fi
fi

install() {
    # policy-rc.d 101 keeps the package's maintainer scripts from starting the service.
    local policy=/usr/sbin/policy-rc.d created=0
    if [ ! -e "$policy" ]; then
        printf '#!/bin/sh\nexit 101\n' | $SUDO tee "$policy" >/dev/null
        $SUDO chmod +x "$policy"
        created=1
    fi
    local rc=0
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q --no-install-recommends influxdb || rc=$?
    if [ "$created" = 1 ]; then $SUDO rm -f "$policy"; fi
    return $rc
}

if ! install; then
    echo "setup/20-influxdb.sh: install failed; refreshing package lists once and retrying"
    $SUDO apt-get update -q
    install
fi

# Debian may enable the unit on install; keep it disabled (tests run their own influxd).
if command -v systemctl >/dev/null 2>&1; then
    $SUDO systemctl disable --now influxdb >/dev/null 2>&1 || true
fi
command -v influxd >/dev/null 2>&1 && echo "influxd installed: $(command -v influxd)"
