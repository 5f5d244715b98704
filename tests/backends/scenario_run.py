"""Run one part of the backend scenario in a private network and PID namespace, and read it.

`unshare -n -p -f --kill-child`: the scenario is PID 1 of its own PID namespace, so
when it ends (or is killed) the kernel kills every process inside — the simulators,
indiserver's driver, `vs record` — and `unshare` itself dies with the pytest worker
that started it (PR_SET_PDEATHSIG). Nothing can outlive a test that timed out.
"""

from __future__ import annotations

import ctypes
import json
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

HERE = Path(__file__).parent
SCENARIO = HERE / "backend_scenario.py"
# one part lasts about 1–1.5 min on a quiet host; a loaded one (4 workers on 2 cores,
# other sessions) may take several times that to start Python, FastAPI and indiserver
SCENARIO_TIMEOUT_S = 720
PR_SET_PDEATHSIG = 1


def skip_reason(kind: str) -> str | None:
    tools = ["unshare", "ip"] + (["indiserver", "indi_simulator_telescope"] if kind == "indi"
                                 else [])
    for tool in tools:
        if shutil.which(tool) is None:
            return f"{tool} is not installed (setup/45-mount-simulators.sh installs the simulators)"
    if kind == "alpaca":
        try:
            import alpaca_simulators  # noqa: F401
        except ImportError:
            return "alpaca-simulators is not installed (setup/45-mount-simulators.sh)"
    probe = subprocess.run(["unshare", "-n", "-p", "-f", "--kill-child", "true"],
                           capture_output=True)
    if probe.returncode != 0:
        return ("cannot create a private network and PID namespace here: "
                f"{probe.stderr.decode()[:200]}")
    return None


def _die_with_parent() -> None:
    libc = ctypes.CDLL(None, use_errno=True)
    libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL)


def run_scenario(kind: str, part: str, out_dir: Path) -> dict:
    """Run `backend_scenario.py KIND PART` and return what it saw (skip if it cannot run)."""
    reason = skip_reason(kind)
    if reason:
        pytest.skip(reason)
    proc = subprocess.Popen(
        ["unshare", "-n", "-p", "-f", "--kill-child", "sh", "-c",
         'ip link set lo up && exec "$0" "$@"', sys.executable, str(SCENARIO), kind, part,
         str(out_dir)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        start_new_session=True, preexec_fn=_die_with_parent)
    try:
        out, err = proc.communicate(timeout=SCENARIO_TIMEOUT_S)
    finally:
        if proc.poll() is None:  # timed out, or the test was interrupted
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == 0, err[-4000:]
    doc = json.loads(out.strip().splitlines()[-1])
    doc["stderr"] = err[-3000:]
    assert not doc["errors"], doc["errors"]
    return doc


def scenario_fixture(kind: str, part: str):
    """The module fixture of a test module: that part's scenario, run once."""

    @pytest.fixture(scope="module")
    def seen(tmp_path_factory) -> dict:
        return run_scenario(kind, part, tmp_path_factory.mktemp(f"{kind}-{part}"))

    return seen
