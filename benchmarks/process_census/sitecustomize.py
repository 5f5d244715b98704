"""For benchmarks/bench_suite.py --processes: every Python process the suite starts says, as it
exits, what it was and the CPU it used.

Python imports `sitecustomize` at start-up from its path, so with this folder on PYTHONPATH
and SUITE_PROCESS_LOG naming a file, each process (pytest, its workers, every `vs server`,
CLI, device and helper a test starts, whatever the depth) appends one JSON line at exit:
its kind (from its command line), its own CPU in seconds and its lifetime. Processes that
are killed (SIGKILL) or that replace their environment are not counted.
"""

from __future__ import annotations

import os

_LOG = os.environ.get("SUITE_PROCESS_LOG")


def _kind(argv: list[str]) -> str:
    """Name what a process was from its command line: the `vs`/tool subcommand, or the script."""
    import sys

    if "-c" in sys.orig_argv:
        code = sys.orig_argv[sys.orig_argv.index("-c") + 1]
        if code.lstrip().startswith("from virtualstar.cli.main import"):  # the tests' `vs`
            return " ".join(["vs", *argv[1:2]])
        return "python -c " + " ".join(code.split())[:60]
    if "-m" in sys.orig_argv:
        module = sys.orig_argv[sys.orig_argv.index("-m") + 1]
        if module == "pytest" or "xdist" in str(sys.modules.get("__main__")):
            return "pytest"
        return f"python -m {module} " + " ".join(argv[1:2])
    script = os.path.basename(argv[0]) if argv else "?"
    if script == "vs":
        return " ".join(["vs", *argv[1:2]])
    return f"{script} " + " ".join(a for a in argv[1:2] if not a.startswith("-"))


if _LOG:
    import atexit
    import json
    import resource
    import sys
    import time

    _t0 = time.monotonic()

    def _born() -> None:  # a child of tests/forkserver.py lives from its fork
        global _t0
        _t0 = time.monotonic()

    os.register_at_fork(after_in_child=_born)

    def _write() -> None:
        use = resource.getrusage(resource.RUSAGE_SELF)
        # a worker is execnet's bootstrap (`python -u -c BOOTSTRAP`); the processes a worker
        # starts inherit PYTEST_XDIST_WORKER, and forked ones execnet too (tests/forkserver.py)
        worker = os.environ.get("PYTEST_XDIST_WORKER", "") and "-c" in sys.orig_argv and \
            "exec(eval(sys.stdin.readline()))" in sys.orig_argv[sys.orig_argv.index("-c") + 1]
        kind = "pytest worker" if worker else _kind(sys.argv)
        line = json.dumps({"kind": kind, "cpu_s": round(use.ru_utime + use.ru_stime, 3),
                           "life_s": round(time.monotonic() - _t0, 3), "pid": os.getpid()})
        try:
            with open(_LOG, "a") as log:  # one short write per process: appends do not interleave
                log.write(line + "\n")
        except OSError:
            pass

    atexit.register(_write)
