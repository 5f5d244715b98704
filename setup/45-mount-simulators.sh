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
# uvicorn's "standard" parser and loop (what `uvicorn[standard]` adds): uvicorn picks them
# itself, and they take a fifth off the simulator's CPU per request (h11 and asyncio's loop
# are pure Python), some 3 s of each Alpaca scenario's CPU
UVICORN_FAST=("httptools==0.9.0" "uvloop==0.23.0")

if "$PY" -c "import alpaca_simulators, httptools, uvloop" 2>/dev/null; then
    echo "alpaca-simulators already installed"
else
    "$PY" -m pip install --quiet --no-compile "$ALPACA_SIMULATORS" "${UVICORN_FAST[@]}"  # (see Makefile)
    echo "alpaca-simulators installed ($ALPACA_SIMULATORS ${UVICORN_FAST[*]})"
fi

if command -v indi_simulator_telescope >/dev/null 2>&1; then
    echo "indi_simulator_telescope already installed: $(command -v indi_simulator_telescope)"
    exit 0
fi
need_apt setup/45-mount-simulators.sh indi-bin "the INDI backend tests will be skipped"
apt_install setup/45-mount-simulators.sh indi-bin
command -v indi_simulator_telescope >/dev/null 2>&1 && \
    echo "indi_simulator_telescope installed: $(command -v indi_simulator_telescope)"
