"""Peak memory of `vs plan` with 10 000 targets (goal ≤ 300 MB; issue 26).

Each measurement is a fresh `vs plan` process (its peak resident set from the kernel,
os.wait4), on a program of N random RA/Dec targets (seeded) at Poznań's default site,
night of 2024-05-18. The reference, in the same run, is the same command on a program of
one target: what the process costs before any target (Python, numpy, scipy, numba, ERFA,
the Earth-orientation table). The first reference run, and the last run, start with an
empty cache directory, as on a fresh machine (the IERS table is then read through astropy,
in a child process whose import and table reading peak near 100 MB above Python's; the
kernel's figure for a process includes its children, so those rows show that child's peak
when it is the higher; later runs take the table from the cache).

    python benchmarks/bench_plan_memory.py [--targets 10000]
"""

from __future__ import annotations

import argparse
import os
import random
import subprocess
import sys
import tempfile
import time
from pathlib import Path

VS = [sys.executable, "-c", "from virtualstar.cli.main import main; main()"]


def write_program(path: Path, n: int, seed: int = 1) -> None:
    rng = random.Random(seed)
    with path.open("w") as f:
        for i in range(n):
            f.write(f'[[target]]\nname = "T{i:05d}"\nradec = "{rng.uniform(0, 360):.4f} '
                    f'{rng.uniform(-89, 89):.4f}"\npriority = {rng.randint(1, 5)}\n'
                    f"duration_s = {rng.choice([300, 600, 900])}\n\n")


def peak(args: list[str], env: dict[str, str]) -> tuple[float, float, int]:
    """Run `vs ARGS`; return (peak RSS in MB, wall s, output lines)."""
    t0 = time.perf_counter()
    proc = subprocess.Popen([*VS, *args], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                            env=env)
    out = proc.stdout.read()
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        raise SystemExit(f"vs {' '.join(args)} failed ({proc.returncode})")
    return usage.ru_maxrss / 1024, time.perf_counter() - t0, out.count(b"\n")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--targets", type=int, default=10_000)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        env = {**os.environ, "VIRTUALSTAR_CACHE_DIR": str(Path(tmp) / "cache")}
        many, one = Path(tmp) / "many.toml", Path(tmp) / "one.toml"
        write_program(many, args.targets)
        write_program(one, 1)
        night = ["--night", "2024-05-18"]
        rows = [("1 target, empty cache (reference)", peak(["plan", str(one), *night], env)),
                ("1 target (reference)", peak(["plan", str(one), *night], env)),
                (f"{args.targets} targets, table", peak(["plan", str(many), *night], env)),
                (f"{args.targets} targets, --json", peak(["plan", str(many), *night, "--json"],
                                                         env))]
        cold = {**env, "VIRTUALSTAR_CACHE_DIR": str(Path(tmp) / "cold")}
        rows.append((f"{args.targets} targets, --json, empty cache",
                     peak(["plan", str(many), *night, "--json"], cold)))
    print(f"vs plan peak memory (resident set, one process each; goal ≤ 300 MB for "
          f"{args.targets} targets)")
    for name, (mb, wall, lines) in rows:
        print(f"  {name:<34} {mb:7.1f} MB   {wall:6.1f} s wall   {lines} lines out")
    base = rows[1][1][0]
    print(f"  per target above the reference: "
          f"{(max(rows[2][1][0], rows[3][1][0]) - base) * 1024 / args.targets:.1f} kB")


if __name__ == "__main__":
    main()
