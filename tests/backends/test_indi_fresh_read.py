"""INDI: a quiet driver is asked for its place again; a frozen one is told from a stalled host.

indi_simulator_telescope pushes EQUATORIAL_EOD_COORD only when the place changed: a held
star leaves it silent. The backend asks again after `FRESH_READ_S` of silence
(``getProperties``); the driver's answer is a report of now. A driver that has answered
nothing for `FRESH_FAIL_S` (frozen with SIGSTOP here, its connection still open) fails
its reads, so the link can call it lost; a shorter silence is a busy host. The simulator runs under
indiserver inside its own network namespace (``unshare -n``), as the other INDI tests.
"""

from __future__ import annotations

import asyncio
import json
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

pytestmark = pytest.mark.skipif(shutil.which("indiserver") is None
                                or shutil.which("indi_simulator_telescope") is None,
                                reason="indiserver / indi_simulator_telescope not installed "
                                "(setup/45-mount-simulators.sh)")


async def _inner() -> dict:
    sys.path.insert(0, str(ROOT))
    from virtualstar.astro import Site
    from virtualstar.server.backends.indi import FRESH_READ_S, IndiDriver

    proc = subprocess.Popen(["indiserver", "-p", "7624", "indi_simulator_telescope"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    out: dict = {"quiet": [], "frozen": []}
    driver = IndiDriver("indi://127.0.0.1:7624/Telescope%20Simulator")
    try:
        for _ in range(100):  # indiserver starting
            try:
                await driver.open(Site(lat_deg=-30.0, lon_deg=20.0, height_m=100.0))
                break
            except OSError:
                await driver.close()
                await asyncio.sleep(0.2)
        await driver.set_tracking(True)  # a held place of date: no push
        reads = 0
        while driver.fresh_answers < 3 and reads < 200:
            rep = await driver.read()
            reads += 1
            out["quiet"].append([rep.received_us is not None, rep.answered])
        out["fresh_reads"], out["fresh_answers"] = driver.fresh_reads, driver.fresh_answers
        out["fresh_read_s"] = FRESH_READ_S
        proc.send_signal(signal.SIGSTOP)  # frozen, its socket still open
        for _ in range(9):  # ~2.3 s each: past FRESH_FAIL_S
            try:
                await driver.read()
                out["frozen"].append("ok")
            except OSError as exc:
                out["frozen"].append(str(exc))
    finally:
        proc.send_signal(signal.SIGCONT)
        proc.terminate()
        await driver.close()
        proc.wait(10)
    return out


def test_a_quiet_indi_driver_answers_fresh_reads_and_a_frozen_one_fails_them():
    try:
        run = subprocess.run(["unshare", "-n", "sh", "-c", 'ip link set lo up && exec "$0" "$@"',
                              sys.executable, __file__], capture_output=True, text=True,
                             timeout=300)
    except FileNotFoundError:
        pytest.skip("unshare is not installed")
    if run.returncode != 0 and "unshare" in run.stderr and "Operation not permitted" in run.stderr:
        pytest.skip("no network namespaces here")
    assert run.returncode == 0, run.stderr[-2000:]
    doc = json.loads(run.stdout.strip().splitlines()[-1])
    # silent between answers, then answered: each answer is a report (with its arrival)
    assert doc["fresh_answers"] >= 3 and doc["fresh_reads"] == doc["fresh_answers"]
    answered = [q for q in doc["quiet"] if q[1]]
    assert len(answered) >= 3 and all(q[0] for q in answered)
    assert any(not q[0] for q in doc["quiet"])  # the silences in between
    # frozen: a few silent reads pass as a busy host's, then every read fails
    assert doc["frozen"][0] == "ok"
    failed = [r for r in doc["frozen"] if r != "ok"]
    assert len(failed) >= 2 and doc["frozen"][-len(failed):] == failed
    assert all("no answer to a fresh read" in r for r in failed)


if __name__ == "__main__":
    print(json.dumps(asyncio.run(_inner())))
