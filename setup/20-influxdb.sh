#!/usr/bin/env bash
# Install InfluxDB 1.x (Debian's `influxdb` package) for the recorder's server store and its tests.
# Idempotent and quick when `influxd` is already on PATH. The system service is neither
# enabled nor started: the tests and users start `influxd` themselves with their own config.
set -euo pipefail
. "$(dirname "$0")/lib/apt.bash"

if command -v influxd >/dev/null 2>&1; then
    echo "influxd already installed: $(command -v influxd)"
    exit 0
fi
need_apt setup/20-influxdb.sh influxdb "the InfluxDB tests will be skipped"

install_without_starting() {
    # policy-rc.d 101 keeps the package's maintainer scripts from starting the service.
    local policy=/usr/sbin/policy-rc.d created=0
    if [ ! -e "$policy" ]; then
        printf '#!/bin/sh\nexit 101\n' | $SUDO tee "$policy" >/dev/null
        $SUDO chmod +x "$policy"
        created=1
    fi
    local rc=0
    apt_get_install "$1" || rc=$?
    if [ "$created" = 1 ]; then $SUDO rm -f "$policy"; fi
    return $rc
}
apt_install setup/20-influxdb.sh influxdb install_without_starting

# Debian may enable the unit on install; keep it disabled (tests run their own influxd).
if command -v systemctl >/dev/null 2>&1; then
    $SUDO systemctl disable --now influxdb >/dev/null 2>&1 || true
fi
command -v influxd >/dev/null 2>&1 && echo "influxd installed: $(command -v influxd)"
