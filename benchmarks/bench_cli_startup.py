"""How fast the command lines start: `vs --help`, `vs status` and every other `--help`
(goal ≤ 0.3 s each; issues 18 and 26).

Each command runs as a fresh process, as a user types it; the median and worst of
--runs wall times are printed beside a bare `python -c pass` measured in the same run.
`vs status` asks a real server: `vs server --emulator --speed max` started here on a
free loopback port (the server's own start-up is not counted). Then every `vs` command's
and subcommand's `--help` and every `pointing-model` one's, --help-runs times each: the
slowest medians are listed (tests/test_import_rules.py keeps their imports light).
Last, the façades' start: importing the Alpaca and the INDI façade (what `vs alpaca` and
`vs-indi` import before serving) beside the same import followed by the whole astronomy
package's modules, which is what the package's __init__ imported before its names loaded
lazily (scipy's splines, numba's SGP4 kernels).

    python benchmarks/bench_cli_startup.py [--runs 15] [--help-runs 5]
"""

from __future__ import annotations

import argparse
import os
import signal
import socket
import statistics
import subprocess
import sys
import time
from pathlib import Path

VS = [sys.executable, "-c", "from virtualstar.cli.main import main; main()"]
PM = [sys.executable, "-c", "from pointing_model.cli import main; main()"]


CPU: dict[str, list[float]] = {}  # CPU seconds (user + system) of each command's runs


def timed(cmd: list[str], runs: int) -> list[float]:
    """Run `cmd` `runs` times; return the wall times, and keep the CPU times in CPU."""
    out = []
    for _ in range(runs):
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        _, _, usage = os.wait4(proc.pid, 0)
        proc.returncode = 0
        out.append(time.perf_counter() - t0)
        CPU.setdefault(" ".join(cmd), []).append(usage.ru_utime + usage.ru_stime)
    return out


def cpu(cmd: list[str]) -> float:
    return statistics.median(CPU[" ".join(cmd)])


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def every_help() -> list[list[str]]:
    """Return the argv of every `vs` and `pointing-model` command's and subcommand's --help."""
    import importlib

    import typer

    from pointing_model.cli import app as pm_app
    from virtualstar.cli.main import COMMANDS

    out = [[*VS, "--help"], [*PM, "--help"]]
    for name, (module, attribute, _) in COMMANDS.items():
        out.append([*VS, name, "--help"])
        target = getattr(importlib.import_module(module), attribute)
        if isinstance(target, typer.Typer):
            out += [[*VS, name, sub, "--help"] for sub in typer.main.get_group(target).commands]
    out += [[*PM, sub, "--help"] for sub in typer.main.get_group(pm_app).commands]
    return out


def label(argv: list[str]) -> str:
    return ("vs " if argv[:3] == VS else "pointing-model ") + " ".join(argv[3:])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=15)
    ap.add_argument("--help-runs", type=int, default=5)
    args = ap.parse_args()
    url = f"ws://127.0.0.1:{free_port()}"
    server = subprocess.Popen([*VS, "server", "--emulator", "--speed", "max", "--listen", url,
                               "--endpoint-port", "0"],
                              stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                              cwd=Path(__file__).parents[1],
                              env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        line = server.stdout.readline()  # "VirtualStar Server on ..." once it listens
        if url not in line:
            raise SystemExit(f"the server did not start (it said {line!r}); nothing to time")
        cmds = [("python -c pass (reference)", [sys.executable, "-c", "pass"]),
                ("vs --help", [*VS, "--help"]),
                ("vs status", [*VS, "status", "--server", url]),
                ("vs slew --help", [*VS, "slew", "--help"]),
                ("vs alpaca --help", [*VS, "alpaca", "--help"]),
                ("vs record --help", [*VS, "record", "--help"])]
        rows = [(name, timed(cmd, args.runs), cmd) for name, cmd in cmds]
    finally:
        server.send_signal(signal.SIGTERM)
        server.wait(30)
    print(f"vs start-up, {args.runs} runs each (per process; goal ≤ 0.3 s; the CPU time, "
          "user + system, is what a busy host does not inflate)")
    for name, times, cmd in rows:
        print(f"  {name:<28} wall median {statistics.median(times):.3f} s, worst "
              f"{max(times):.3f} s   CPU median {cpu(cmd):.3f} s")
    helps = []
    for argv in every_help():
        wall = statistics.median(timed(argv, args.help_runs))
        helps.append((label(argv), wall, cpu(argv)))
    helps.sort(key=lambda x: -x[2])
    print(f"every --help ({len(helps)} commands, {args.help_runs} runs each): CPU median of the "
          f"slowest {helps[0][2]:.3f} s ({helps[0][0]}), of all "
          f"{statistics.median([h[2] for h in helps]):.3f} s; wall median of all "
          f"{statistics.median([h[1] for h in helps]):.3f} s; "
          f"{sum(h[2] > 0.3 for h in helps)} over 0.3 s of CPU")
    for name, wall, cpu_s in helps[:5]:
        print(f"  {name:<40} CPU median {cpu_s:.3f} s   wall median {wall:.3f} s")
    facades(args.runs)


_EVERY_ASTRO_MODULE = ("; import virtualstar.astro.altaz, virtualstar.astro.avoidance, "
                       "virtualstar.astro.bodies, virtualstar.astro.events, "
                       "virtualstar.astro.observed, virtualstar.astro.satellites, "
                       "virtualstar.astro.slew, virtualstar.astro.stars, virtualstar.astro.targets")


def facades(runs: int) -> None:
    """The façades' import, beside it with every astronomy module (the eager package)."""
    print(f"façade start-up, {runs} runs each (CPU median: ours, then with the whole astronomy "
          "package as its __init__ used to import it)")
    for module in ("virtualstar.alpaca", "virtualstar.indi.driver"):
        ours = [sys.executable, "-c", f"import {module}"]
        eager = [sys.executable, "-c", f"import {module}{_EVERY_ASTRO_MODULE}"]
        timed(ours, runs)
        timed(eager, runs)
        print(f"  import {module:<24} CPU median {cpu(ours):.3f} s   with every astronomy "
              f"module {cpu(eager):.3f} s")


if __name__ == "__main__":
    main()
