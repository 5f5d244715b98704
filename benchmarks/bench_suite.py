"""The suite's own speed: `make test`'s pytest, wall time beside what the CPU it used allows
(goal ≤ 4 min on a quiet 2-core machine, ≤ 6 min beside two CPU burners; issue 26).

One run of the suite exactly as `make test` runs it (`pytest -q -n WORKERS --dist loadscope
--no-loadscope-reorder`), optionally beside N processes that burn a core each (as
`make test-under-load` does). The
reference, measured in the same run, is the CPU the suite's processes used (the kernel's
figure for this process's children: pytest, its workers, the servers, browsers and compilers
they start) divided by the cores left to it: the wall time a perfectly packed run would take.
The difference is what waiting (real-time tests, a worker's last long module) costs. Before and
after the run it times a host probe (a fresh interpreter importing the server, and a pure-Python
loop): this VM's speed for the suite has varied by 1.7× over hours, and runs compare only beside it.

With `--modules N` it also prints the N modules that used the most CPU (own + the children
they waited for; benchmarks/suite_cpu_plugin.py), with their wall time: where to cut.
With `--processes` it also counts every Python process the suite started, by kind (pytest
workers, `vs server`, other `vs` commands, devices, helpers), with the CPU each kind used
(benchmarks/process_census/sitecustomize.py): what a process's start-up costs the suite.

    python benchmarks/bench_suite.py [--workers 4] [--burners 0|2] [--modules 30]
                                     [--processes] [-- extra pytest args, e.g. --durations=40]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _suite_env() -> dict[str, str]:
    """The environment `make test` gives pytest: bytecode written (the Makefile unexports
    PYTHONDONTWRITEBYTECODE, so that its hundreds of processes do not compile the same sources
    again)."""
    env = dict(os.environ)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    return env


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--workers", type=int, default=5, help="pytest-xdist workers (make test: 5)")
    ap.add_argument("--burners", type=int, default=0,
                    help="processes burning a core each beside the suite (test-under-load: 2)")
    ap.add_argument("--modules", type=int, default=0, metavar="N",
                    help="print the N modules that used the most CPU")
    ap.add_argument("--processes", action="store_true",
                    help="count the Python processes the suite started, and their CPU, by kind")
    ap.add_argument("--log", type=Path, default=None,
                    help="write pytest's whole output here (default: a file in the temporary "
                         "directory when a test failed, so that its message is never lost)")
    ap.add_argument("pytest_args", nargs="*", help="more pytest arguments (after --)")
    args = ap.parse_args()
    env = _suite_env()
    per_module = tempfile.TemporaryDirectory(prefix="suite-cpu-") if args.modules else None
    plugin: list[str] = []
    if per_module is not None:
        env["SUITE_CPU_DIR"] = per_module.name
        env["PYTHONPATH"] = os.pathsep.join(
            [str(ROOT / "benchmarks"), *filter(None, [env.get("PYTHONPATH")])])
        plugin = ["-p", "suite_cpu_plugin"]
    census = tempfile.TemporaryDirectory(prefix="suite-processes-") if args.processes else None
    if census is not None:
        env["SUITE_PROCESS_LOG"] = str(Path(census.name) / "processes.jsonl")
        env["PYTHONPATH"] = os.pathsep.join(
            [str(ROOT / "benchmarks" / "process_census"), *filter(None, [env.get("PYTHONPATH")])])
    cores = os.cpu_count() or 1
    load_before = os.getloadavg()[0]
    probe_before = _host_probe(env)
    burners = [subprocess.Popen([sys.executable, "-c", "while True: pass"])
               for _ in range(args.burners)]
    try:
        before = os.times()
        t0 = time.monotonic()
        proc = subprocess.run(
            [sys.executable, "-m", "pytest", "-q", "-n", str(args.workers), "--dist",
             "loadscope", "--no-loadscope-reorder", "-p", "no:cacheprovider", *plugin,
             *args.pytest_args],
            cwd=ROOT, capture_output=True, text=True, env=env)
        wall_s = time.monotonic() - t0
        after = os.times()
    finally:
        for b in burners:
            b.kill()
            b.wait()
    cpu_s = (after.children_user - before.children_user
             + after.children_system - before.children_system)
    # the burners are children too, but they have not been waited for by the time `after` is
    # read: their CPU is not in cpu_s
    share = cores * args.workers / (args.workers + args.burners) if args.burners else cores
    share = min(share, cores)
    probe_after = _host_probe(env)
    summary = [line for line in proc.stdout.splitlines() if re.search(r"\d+ (passed|failed)", line)]
    print(f"machine: {cores} cores, 1-min load before the run {load_before:.2f}, "
          f"{args.burners} burner(s)")
    print(f"host probe before / after the run (median of 3, CPU s): importing the server "
          f"{probe_before[0]:.2f} / {probe_after[0]:.2f}, a pure-Python loop "
          f"{probe_before[1]:.2f} / {probe_after[1]:.2f}")
    print(f"suite: {summary[-1] if summary else proc.stdout[-500:]}")
    for line in proc.stdout.splitlines():
        if line.startswith(("FAILED", "ERROR")):
            print(f"  {line[:300]}")
    log = args.log
    if log is None and proc.returncode != 0:
        log = Path(tempfile.mkstemp(prefix="bench-suite-", suffix=".log")[1])
    if log is not None:
        log.write_text(proc.stdout + proc.stderr)
        print(f"  pytest's whole output (the failures' messages): {log}")
    print(f"ours: wall {wall_s:.0f} s ({wall_s / 60:.1f} min) with {args.workers} workers")
    print(f"reference: CPU used {cpu_s:.0f} s / {share:.2f} cores left to it = "
          f"{cpu_s / share:.0f} s, a perfectly packed run ({wall_s / (cpu_s / share):.2f}× that)")
    if per_module is not None:
        with per_module:
            _print_modules(Path(per_module.name), args.modules)
    if census is not None:
        with census:
            _print_processes(Path(census.name) / "processes.jsonl", cpu_s)
    for line in proc.stdout.splitlines():  # --durations, if asked for
        if re.match(r"\d+\.\d+s (setup|call|teardown) ", line):
            print(f"  {line}")
    return proc.returncode


# A fresh interpreter imports the server (about a thousand modules: what every worker, server
# and CLI of the suite does first), then runs a loop that touches no new memory. The suite's
# CPU follows the first: on this VM the same suite has used 330 s and 580 s of CPU hours apart
# while the loop timed the same, so runs on different days compare only beside this figure.
_PROBE = """
import time
t = time.process_time()
import virtualstar.server.server
imported = time.process_time() - t
t = time.process_time()
x = 0
for i in range(5_000_000):
    x += i
print(imported, time.process_time() - t)
"""


def _host_probe(env: dict[str, str]) -> tuple[float, float]:
    """Median CPU seconds of the probe's import and loop over three fresh interpreters."""
    runs = sorted(tuple(map(float, subprocess.run(
        [sys.executable, "-c", _PROBE], cwd=ROOT, env=env, capture_output=True, text=True,
        check=True).stdout.split())) for _ in range(3))
    return statistics.median(r[0] for r in runs), statistics.median(r[1] for r in runs)


def _print_modules(directory: Path, n: int) -> None:
    modules: dict[str, list[float]] = {}
    own = children = 0.0
    for path in directory.glob("*.json"):
        if path.stem == "main" and len(list(directory.glob("gw*.json"))):
            continue  # the xdist controller runs no test
        data = json.loads(path.read_text())
        own += data["own_cpu_s"]
        children += data["children_cpu_s"]
        for name, row in data["modules"].items():
            total = modules.setdefault(name, [0.0, 0.0, 0.0, 0])
            for i, value in enumerate(row):
                total[i] += value
    in_tests = sum(r[0] + r[1] for r in modules.values())
    print(f"per module: the test processes used {own:.0f} s of CPU themselves and "
          f"{children:.0f} s in children they reaped; {in_tests:.0f} s inside tests "
          f"(the rest: start-up, collection, children reaped after their test)")
    print("   CPU s   own  children   wall s  tests  module")
    for name, (o, c, wall, count) in sorted(modules.items(),
                                            key=lambda kv: -(kv[1][0] + kv[1][1]))[:n]:
        print(f"  {o + c:6.1f} {o:5.1f} {c:9.1f} {wall:8.1f} {count:6d}  {name}")
    _print_timeline(directory)


def _print_timeline(directory: Path) -> None:
    """Each worker's start-up, busy span and idle end: where the run waits for its last modules."""
    workers = {p.stem: json.loads(p.read_text()) for p in sorted(directory.glob("gw*.json"))}
    if not workers:
        return
    t0 = min(w["process_start"] for w in workers.values())
    end = max(w["session_end"] for w in workers.values())
    print("timeline (s from the first worker's start): worker, first test, last test's end, "
          "idle before the suite's end, its last modules")
    for name, w in workers.items():
        spans = sorted(w["spans"].items(), key=lambda kv: kv[1][1])
        if not spans:
            continue
        first = min(s for s, _ in w["spans"].values()) - t0
        last = spans[-1][1][1] - t0
        tail = ", ".join(f"{m.removeprefix('tests/')} {s - t0:.0f}-{e - t0:.0f}"
                         for m, (s, e) in spans[-3:])
        print(f"  {name}: {first:5.1f} {last:6.1f} {end - t0 - last:5.1f}  {tail}")
    _print_windows(workers, t0, end)


def _print_windows(workers: dict[str, dict], t0: float, end: float, step_s: float = 10.0) -> None:
    """Per stretch of the run, the cores its running modules kept busy (each module's CPU
    spread evenly over its wall time), and what ran: a stretch well below the core count is
    one where too many modules wait on real time together (tests/session_order.py)."""
    running = []  # (start, end, cores used, module), times relative to t0
    for w in workers.values():
        for name, (start, stop) in w["spans"].items():
            own, children = w["modules"][name][:2]
            running.append((start - t0, stop - t0, (own + children) / max(stop - start, 1e-3),
                            name.removeprefix("tests/")))
    print(f"busy cores per {step_s:.0f} s (estimated from each module's CPU over its wall), "
          "below 1.5: the modules running")
    t = 0.0
    while t < end - t0:
        busy, names = 0.0, []
        for start, stop, cores, name in running:
            overlap = min(stop, t + step_s) - max(start, t)
            if overlap > 0:
                busy += cores * overlap / step_s
                names.append(f"{name} ({cores:.2f})")
        print(f"  {t:4.0f}-{t + step_s:4.0f} s: {busy:4.2f}" + (f"  {', '.join(names)}"
                                                          if busy < 1.5 else ""))
        t += step_s


def _print_processes(log: Path, cpu_s: float) -> None:
    kinds: dict[str, list[float]] = {}  # kind: [count, CPU s, lifetime s]
    lines = log.read_text().splitlines() if log.exists() else []
    for line in lines:
        row = json.loads(line)
        total = kinds.setdefault(row["kind"], [0, 0.0, 0.0])
        total[0] += 1
        total[1] += row["cpu_s"]
        total[2] += row["life_s"]
    counted = sum(k[1] for k in kinds.values())
    print(f"processes: {len(lines)} Python processes reported {counted:.0f} s of the {cpu_s:.0f} s "
          f"of CPU (the rest: browsers, simulators, compilers, killed processes)")
    print("  count   CPU s  CPU s each  life s  kind")
    for kind, (n, c, life) in sorted(kinds.items(), key=lambda kv: -kv[1][1])[:40]:
        print(f"  {n:5d} {c:7.1f} {c / n:11.2f} {life:7.0f}  {kind}")


if __name__ == "__main__":
    sys.exit(main())
