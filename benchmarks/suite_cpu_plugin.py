"""A pytest plugin for benchmarks/bench_suite.py: the CPU each test module used, per process.

Each process that runs tests (pytest, or each pytest-xdist worker) adds, per module, its own
CPU and that of the children it reaped (servers, CLIs, browsers a test waited for; and those
tests/forkserver.py forked for it, which the fork server reaps) between
the start and the end of each test, and the wall time; at the end it writes
`$SUITE_CPU_DIR/<worker>.json`. Children still running when a test ends (a module's server
stopped in its teardown) count in the test that reaps them.

    pytest -p suite_cpu_plugin ...   (with benchmarks/ on PYTHONPATH and SUITE_CPU_DIR set)
"""

from __future__ import annotations

import json
import os
import resource
import sys
import time
from pathlib import Path

_modules: dict[str, list[float]] = {}  # module: [own CPU s, children's CPU s, wall s, tests]
_started: dict[str, tuple[float, float, float]] = {}
# module: [first test's start, last test's end] in Unix time, so that the workers' timelines
# can be laid side by side (where the run's tail is: one worker busy while the others wait)
_spans: dict[str, list[float]] = {}
_process_start = time.time()


def _cpu_s() -> tuple[float, float]:
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    # the children tests/forkserver.py forked for this process are the fork server's, which
    # tells their CPU as each is waited for
    forked = getattr(sys.modules.get("forkserver"), "reaped_cpu_s", 0.0)
    return own.ru_utime + own.ru_stime, children.ru_utime + children.ru_stime + forked


def pytest_runtest_protocol(item, nextitem) -> None:
    _started[item.nodeid] = (*_cpu_s(), time.monotonic())
    _spans.setdefault(item.nodeid.split("::")[0], [time.time(), 0.0])


def pytest_runtest_logfinish(nodeid, location) -> None:
    if nodeid not in _started:
        return
    own0, children0, wall0 = _started.pop(nodeid)
    own1, children1 = _cpu_s()
    row = _modules.setdefault(nodeid.split("::")[0], [0.0, 0.0, 0.0, 0])
    row[0] += own1 - own0
    row[1] += children1 - children0
    row[2] += time.monotonic() - wall0
    row[3] += 1
    _spans[nodeid.split("::")[0]][1] = time.time()


def pytest_sessionfinish(session) -> None:
    out = os.environ.get("SUITE_CPU_DIR")
    if not out:
        return
    own, children = _cpu_s()
    name = os.environ.get("PYTEST_XDIST_WORKER", "main")
    Path(out, f"{name}.json").write_text(json.dumps(
        {"modules": _modules, "own_cpu_s": own, "children_cpu_s": children, "spans": _spans,
         "process_start": _process_start, "session_end": time.time()}))
