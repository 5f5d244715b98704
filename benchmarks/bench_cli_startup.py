"""How fast the `vs` command line starts: `vs --help` and `vs status` (goal ≤ 0.3 s each).

Each command runs as a fresh process, as a user types it; the median and worst of
--runs wall times are printed beside a bare `python -c pass` measured in the same run.
`vs status` asks a real server: `vs server --emulator --speed max` started here on a
free loopback port (the server's own start-up is not counted).

    python benchmarks/bench_cli_startup.py [--runs 15]
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=15)
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
        rows = [("python -c pass (reference)", timed([sys.executable, "-c", "pass"], args.runs)),
                ("vs --help", timed([*VS, "--help"], args.runs)),
                ("vs status", timed([*VS, "status", "--server", url], args.runs)),
                ("vs slew --help", timed([*VS, "slew", "--help"], args.runs))]
    finally:
        server.send_signal(signal.SIGTERM)
        server.wait(30)
    print(f"vs start-up, {args.runs} runs each (wall time per process; goal ≤ 0.3 s)")
    for name, times in rows:
        print(f"  {name:<28} median {statistics.median(times):.3f} s   worst {max(times):.3f} s")


if __name__ == "__main__":
    main()
