"""How fast the command lines start: `vs --help`, `vs status` and every other `--help`
(goal ≤ 0.3 s each; issues 18 and 26).

Each command runs as a fresh process, as a user types it; the median and worst of
--runs wall times are printed beside a bare `python -c pass` measured in the same run.
`vs status` asks a real server: `vs server --emulator --speed max` started here on a
free loopback port (the server's own start-up is not counted). Then every `vs` command's
and subcommand's `--help` and every `pointing-model` one's, --help-runs times each: the
slowest medians are listed (tests/test_import_rules.py keeps their imports light).

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


def timed(cmd: list[str], runs: int) -> list[float]:
    out = []
    for _ in range(runs):
        t0 = time.perf_counter()
        subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=False)
        out.append(time.perf_counter() - t0)
    return out


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
    server = subprocess.Popen([*VS, "server", "--emulator", "--speed", "max", "--listen", url],
                              stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                              cwd=Path(__file__).parents[1],
                              env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        line = server.stdout.readline()  # "VirtualStar Server on ..." once it listens
        if url not in line:
            raise SystemExit(f"the server did not start (it said {line!r}); nothing to time")
        rows = [("python -c pass (reference)", timed([sys.executable, "-c", "pass"], args.runs)),
                ("vs --help", timed([*VS, "--help"], args.runs)),
                ("vs status", timed([*VS, "status", "--server", url], args.runs)),
                ("vs slew --help", timed([*VS, "slew", "--help"], args.runs)),
                ("vs alpaca --help", timed([*VS, "alpaca", "--help"], args.runs)),
                ("vs record --help", timed([*VS, "record", "--help"], args.runs))]
    finally:
        server.send_signal(signal.SIGTERM)
        server.wait(30)
    print(f"vs start-up, {args.runs} runs each (wall time per process; goal ≤ 0.3 s)")
    for name, times in rows:
        print(f"  {name:<28} median {statistics.median(times):.3f} s   worst {max(times):.3f} s")
    helps = [(label(argv), statistics.median(timed(argv, args.help_runs)))
             for argv in every_help()]
    helps.sort(key=lambda x: -x[1])
    over = [h for h in helps if h[1] > 0.3]
    print(f"every --help ({len(helps)} commands, {args.help_runs} runs each): median of the "
          f"slowest {helps[0][1]:.3f} s ({helps[0][0]}), of all {statistics.median([h[1] for h in helps]):.3f} s; "
          f"{len(over)} over 0.3 s")
    for name, median in helps[:5]:
        print(f"  {name:<40} median {median:.3f} s")


if __name__ == "__main__":
    main()
