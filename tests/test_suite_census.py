"""benchmarks/bench_suite.py --processes: every Python process started with the census on its
path reports what it was and the CPU it used, however deep below the one that started it."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

CENSUS = Path(__file__).resolve().parents[1] / "benchmarks" / "process_census"

# a parent that burns 0.3 s of CPU, then runs `vs server --help` as the tests run `vs`; it
# imports execnet, as a child forked from tests/forkserver.py holds it, and is no xdist worker
PARENT = """
import execnet, subprocess, sys, time
t = time.process_time()
while time.process_time() - t < 0.3:
    pass
subprocess.run([sys.executable, "-c", "from virtualstar.cli.main import main; main()",
                "server", "--help"], capture_output=True, check=True)
"""


def test_each_process_reports_its_kind_and_the_cpu_it_used(tmp_path):
    log = tmp_path / "processes.jsonl"
    env = {**os.environ, "SUITE_PROCESS_LOG": str(log), "PYTEST_XDIST_WORKER": "gw9",
           "PYTHONPATH": os.pathsep.join([str(CENSUS), os.environ.get("PYTHONPATH", "")])}
    subprocess.run([sys.executable, "-c", PARENT], env=env, check=True, timeout=120)
    rows = [json.loads(line) for line in log.read_text().splitlines()]
    kinds = {row["kind"]: row for row in rows}
    assert len(rows) == 2 and "vs server" in kinds, rows
    burner = next(row for row in rows if row["kind"] != "vs server")
    assert burner["kind"].startswith("python -c import execnet, subprocess, sys"), burner
    assert burner["cpu_s"] >= 0.3  # its own loop, not counting the child it waited for
    assert 0 < kinds["vs server"]["cpu_s"] < burner["cpu_s"] + 5
    assert burner["life_s"] >= kinds["vs server"]["life_s"]
