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
import time
from pathlib import Path

import pytest

HERE = Path(__file__).parent
SCENARIO = HERE / "backend_scenario.py"
# one part lasts about 0.5–1 min on a quiet host; a loaded one (4 workers on 2 cores,
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


def run_parts(kind: str, parts: tuple[str, ...], out_dir: Path) -> dict[str, dict]:
    """Run `backend_scenario.py KIND PART` for each part at once, each on its own simulator
    in its own namespaces (most of a part's wall is waiting on real-time motion: side by
    side, a module takes as long as its longest part); return what each saw."""
    reason = skip_reason(kind)
    if reason:
        pytest.skip(reason)
    running = {}
    try:
        for part in parts:
            folder = out_dir / part
            folder.mkdir(parents=True, exist_ok=True)
            out, err = open(folder / "stdout", "w+"), open(folder / "stderr", "w+")  # noqa: SIM115
            running[part] = (subprocess.Popen(
                ["unshare", "-n", "-p", "-f", "--kill-child", "sh", "-c",
                 'ip link set lo up && exec "$0" "$@"', sys.executable, str(SCENARIO), kind,
                 part, str(folder)],
                stdout=out, stderr=err, text=True, start_new_session=True,
                preexec_fn=_die_with_parent), out, err)
        deadline = time.monotonic() + SCENARIO_TIMEOUT_S
        for proc, _out, _err in running.values():
            proc.wait(timeout=max(1.0, deadline - time.monotonic()))
    finally:
        for proc, _out, _err in running.values():
            if proc.poll() is None:  # timed out, or the test was interrupted
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
    seen = {}
    for part, (proc, out, err) in running.items():
        with out, err:
            out.seek(0)
            err.seek(0)
            text, errors = out.read(), err.read()
        assert proc.returncode == 0, f"{part}: {errors[-4000:]}"
        doc = json.loads(text.strip().splitlines()[-1])
        doc["stderr"] = errors[-3000:]
        assert not doc["errors"], (part, doc["errors"])
        seen[part] = doc
    return seen


def scenario_fixtures(kind: str, *parts: str) -> list:
    """The module fixtures of a test module: its parts' scenarios, run once and at once;
    `seen` is the first part's, `seen_<part>` each other's."""

    @pytest.fixture(scope="module")
    def seen_parts(tmp_path_factory) -> dict:
        return run_parts(kind, parts, tmp_path_factory.mktemp(f"{kind}-{'-'.join(parts)}"))

    def one(part: str, name: str):
        @pytest.fixture(scope="module", name=name)
        def seen_part(seen_parts) -> dict:
            return seen_parts[part]

        return seen_part

    return [seen_parts] + [one(part, "seen" if k == 0 else f"seen_{part}")
                           for k, part in enumerate(parts)]
