"""The JavaScript ASTCom client's unit tests (node's test runner) against a live Python endpoint."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest
from panel_helpers import PANEL_DIR, PASSWORD, node, start_example_device

RATE_HZ = 10_000


@pytest.fixture(scope="module")
def example_endpoint():
    device = start_example_device(RATE_HZ)
    yield device
    device.stop()


def test_js_client_and_panel_unit_tests_pass_against_the_python_example_device(example_endpoint):
    ws_url, tcp_url = example_endpoint.urls
    assert ws_url.startswith("ws://") and tcp_url.startswith("tcp://")
    env = {"VS_PYTHON": sys.executable, "ASTCOM_URL": ws_url, "ASTCOM_TCP_URL": tcp_url, "ASTCOM_PASSWORD": PASSWORD,
           "ASTCOM_RATE_HZ": str(RATE_HZ), "PATH": "/usr/bin:/bin:/usr/local/bin"}
    # Node 20 gives JSON.parse the numbers' source text (0.0 vs 0, src/eventlog.js) behind a flag
    run = subprocess.run([node(), "--harmony-json-parse-with-source", "--test",
                          "--test-reporter=spec", "test/unit/"], cwd=PANEL_DIR,
                         env=env, capture_output=True, text=True,
                         timeout=600)  # a hang guard only: a loaded host (load 27 seen) is slow
    report = run.stdout + run.stderr
    assert run.returncode == 0, report
    # every test of every file ran and none was skipped
    written = sum(len(re.findall(r"^test\(", f.read_text(), re.M))
                  for f in (PANEL_DIR / "test" / "unit").glob("*.test.js"))
    assert written >= 20
    assert f"ℹ pass {written}" in report and "ℹ fail 0" in report and "ℹ skipped 0" in report, report
