#!/usr/bin/env bash
# Install the two mount simulators the tests of the Alpaca and INDI backends drive (simulators
# we did not write): ASCOM's alpaca-simulators (PyPI, MIT; a FastAPI server, so it goes into
# the project's .venv, pinned: its telescope's behaviour is what the tests were written
# against) and INDI's indi_simulator_telescope (Debian's indi-bin, with indiserver).
# Idempotent and quick when both are there.
set -euo pipefail
. "$(dirname "$0")/lib/apt.bash"

PY="${PYTHON_VENV:-.venv/bin/python}"
ALPACA_SIMULATORS="alpaca-simulators==1.3.2"

if "$PY" -c "import alpaca_simulators" 2>/dev/null; then
    echo "alpaca-simulators already installed"
else
    "$PY" -m pip install --quiet "$ALPACA_SIMULATORS"
    echo "alpaca-simulators installed ($ALPACA_SIMULATORS)"
fi

if command -v indi_simulator_telescope >/dev/null 2>&1; then
    echo "indi_simulator_telescope already installed: $(command -v indi_simulator_telescope)"
    exit 0
fi
need_apt setup/45-mount-simulators.sh indi-bin "the INDI backend tests will be skipped"
apt_install setup/45-mount-simulators.sh indi-bin
command -v indi_simulator_telescope >/dev/null 2>&1 && \
    echo "indi_simulator_telescope installed: $(command -v indi_simulator_telescope)"
