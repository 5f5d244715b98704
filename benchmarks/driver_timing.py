"""How the two simulators take a rate: the facts the rate loop's bound and predictor rest on.

    python benchmarks/driver_timing.py [--only alpaca|indi]

Each simulator runs in a private network namespace (indiserver binds every interface),
on loopback, driven by plain HTTP / raw INDI XML (none of our code), and the script
prints:

* the update period: Alpaca — whether two reads a few ms apart give two places (a place
  computed at each read); INDI — the interval between pushes of EQUATORIAL_EOD_COORD;
* when a rate takes effect: a rate step sent at a random moment between two updates;
  the share of that update interval that moved at the *new* rate (1 = from the previous
  update on, retroactively; the time left after the command / the interval = at once;
  0 = only from the next update);
* the rate resolution: a rate that is no round number, measured over seconds;
* INDI's property timestamps (their resolution) and its refusal to reverse an axis while
  tracking at custom rates (libindi: "Cannot reverse tracking while tracking is engaged").
"""

from __future__ import annotations

import argparse
import http.client
import json
import os
import random
import re
import socket
import statistics
import subprocess
import sys
import time
import urllib.parse

SIDEREAL = 15.041067  # arcsec/s, the INDI simulator's own figure
_last_request = [(0.0, 0.0)]  # (start, end) of the last Alpaca request (s)


def wait_port(port: int) -> None:
    for _ in range(1200):  # a loaded host: the Alpaca simulator may need a minute
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.05)
    raise RuntimeError(f"nothing listens on {port}")


# ---------------------------------------------------------------------- Alpaca
def alpaca() -> None:
    port = 18124
    proc = subprocess.Popen([sys.executable, "-m", "alpaca_simulators.run_simulator", "--host",
                             "127.0.0.1", "--port", str(port)], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    try:
        wait_port(port)
        conn = http.client.HTTPConnection("127.0.0.1", port, timeout=5)
        base = "/api/v1/telescope/0/"

        def call(method: str, member: str, **kw):
            q = urllib.parse.urlencode({"ClientID": 5, "ClientTransactionID": 1, **kw})
            t0 = time.time()
            if method == "GET":
                conn.request("GET", f"{base}{member}?{q}")
            else:
                conn.request("PUT", base + member, q,
                             {"Content-Type": "application/x-www-form-urlencoded"})
            doc = json.loads(conn.getresponse().read())
            t1 = time.time()
            _last_request[0] = (t0, t1)
            return (t1 + t0) / 2, doc.get("Value")

        call("PUT", "connected", Connected="true")
        call("PUT", "unpark")
        call("PUT", "tracking", Tracking="true")
        call("PUT", "moveaxis", Axis=0, Rate="0.5")
        time.sleep(0.3)
        a, b = call("GET", "rightascension"), call("GET", "rightascension")
        moved = (b[1] - a[1]) * 15 * 3600
        print(f"[alpaca] two reads {1e3 * (b[0] - a[0]):.1f} ms apart at 0.5°/s: moved "
              f"{moved:.2f}″ (expected {1800 * (b[0] - a[0]):.2f}″): the place is computed at "
              "every read of RightAscension/Declination (and every 100 ms by its own thread)")
        shares = []
        for k in range(12):
            old, new = (0.5, 1.0) if k % 2 == 0 else (1.0, 0.5)
            t0, ra0 = call("GET", "rightascension")
            time.sleep(random.uniform(0.01, 0.07))
            tc, _ = call("PUT", "moveaxis", Axis=0, Rate=repr(new))
            time.sleep(max(0.0, t0 + 0.08 - time.time()))
            t1, ra1 = call("GET", "rightascension")
            d = (ra1 - ra0) * 15.0  # degrees
            shares.append(((d - old * (t1 - t0)) / ((new - old) * (t1 - t0)),
                           (t1 - tc) / (t1 - t0)))
        print(f"[alpaca] MoveAxis sent inside an 80-ms interval between two reads (12 steps): "
              f"share moved at the new rate {statistics.median(s for s, _ in shares):.3f} "
              f"(median; at once would be {statistics.median(i for _, i in shares):.2f}): "
              "in force from the previous read (the driver's last update) on")
        devicestate_instants(call)
        rate = 0.123456789
        call("PUT", "moveaxis", Axis=0, Rate=repr(rate))
        t0, ra0 = call("GET", "rightascension")
        time.sleep(3.0)
        t1, ra1 = call("GET", "rightascension")
        got = (ra1 - ra0) * 15 / (t1 - t0)
        print(f"[alpaca] MoveAxis {rate}°/s measured over 3 s: {got:.9f}°/s "
              f"(difference {abs(got - rate) * 3600:.4f}″/s, the read times' share): the rate "
              "is a double, no step")
        call("PUT", "moveaxis", Axis=0, Rate="0")
    finally:
        proc.terminate()
        proc.wait(10)


def devicestate_instants(call) -> None:
    """DeviceState's place and the instant it describes (what bench_backends judges): the
    instant recovered from its Altitude/Azimuth must fall inside the RightAscension read
    that set the place just before (that read advances the place to its own moment)."""
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from datetime import datetime

    from bench_backends import simulator_instant

    lat, lon = float(call("GET", "sitelatitude")[1]), float(call("GET", "sitelongitude")[1])
    inside, where, after_mid, ddec = 0, [], [], []
    n = 20
    for _ in range(n):
        t_mid, _ra = call("GET", "rightascension")
        t0, t1 = _last_request[0]
        _, values = call("GET", "devicestate")
        v = {d["Name"]: d["Value"] for d in values}
        stamp = datetime.fromisoformat(v["TimeStamp"]).timestamp()
        t, dec = simulator_instant(v["RightAscension"], v["Altitude"], v["Azimuth"], lat, lon,
                                   stamp)
        t = float(t)
        inside += t0 <= t <= t1
        where.append((t - t0) / (t1 - t0))
        after_mid.append((t_mid - t) * 1e3)
        ddec.append(abs(float(dec) - v["Declination"]) * 3600)
        time.sleep(random.uniform(0.01, 0.05))
    print(f"[alpaca] DeviceState's place at the instant its Altitude/Azimuth give back: inside "
          f"the RightAscension read that set it {inside}/{n} times, at {statistics.median(where):.2f}"
          f" of the read (median; the read's middle is {statistics.median(after_mid):+.2f} ms "
          f"from it), its declination given back to {max(ddec):.0e}″: DeviceState places carry "
          "their own time (bench_backends judges them there)")


# ---------------------------------------------------------------------- INDI
class Indi:
    def __init__(self, port: int, device: str) -> None:
        self.s = socket.create_connection(("127.0.0.1", port))
        self.device = device
        self.buf = b""
        self.places: list[tuple[float, str, float, float]] = []  # arrival, timestamp, ra, dec
        self.messages: list[str] = []
        self.s.sendall(b'<getProperties version="1.7"/>')

    def send(self, kind: str, name: str, members: dict) -> None:
        one = "oneSwitch" if kind == "Switch" else "oneNumber"
        body = "".join(f'<{one} name="{k}">{v}</{one}>' for k, v in members.items())
        self.s.sendall(f'<new{kind}Vector device="{self.device}" name="{name}">{body}'
                       f'</new{kind}Vector>'.encode())

    def pump(self, seconds: float) -> None:
        end = time.time() + seconds
        self.s.settimeout(0.02)
        while time.time() < end:
            try:
                data = self.s.recv(65536)
            except TimeoutError:
                continue
            t = time.time()
            self.buf += data
            for m in re.finditer(rb'message="([^"]*)"', data):
                self.messages.append(m.group(1).decode(errors="replace"))
            while True:
                m = re.search(rb'<setNumberVector[^>]*name="EQUATORIAL_EOD_COORD".*?'
                              rb'</setNumberVector>', self.buf, re.S)
                if not m:
                    break
                block, self.buf = m.group(0), self.buf[m.end():]
                stamp = re.search(rb'timestamp="([^"]*)"', block)
                vals = dict(re.findall(rb'name="(RA|DEC)"[^>]*>\s*([^<\s]+)', block))
                self.places.append((t, stamp.group(1).decode() if stamp else "",
                                    float(vals[b"RA"]), float(vals[b"DEC"])))
            self.buf = self.buf[-200_000:]


def indi() -> None:
    port, device = 7624, "Telescope Simulator"
    proc = subprocess.Popen(["indiserver", "-p", str(port), "indi_simulator_telescope"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        wait_port(port)
        time.sleep(1.0)
        c = Indi(port, device)
        c.pump(1.0)
        c.send("Switch", "CONNECTION", {"CONNECT": "On"})
        c.pump(2.0)
        c.send("Switch", "TELESCOPE_TRACK_STATE", {"TRACK_ON": "On", "TRACK_OFF": "Off"})
        c.pump(1.0)
        # the RA member is the axis rate (sidereal included): the place moves at SIDEREAL - x
        c.send("Number", "TELESCOPE_TRACK_RATE", {"TRACK_RATE_RA": SIDEREAL - 1800.0,
                                                  "TRACK_RATE_DE": 900.0})
        c.send("Switch", "TELESCOPE_TRACK_MODE", {"TRACK_SIDEREAL": "Off",
                                                  "TRACK_CUSTOM": "On"})
        c.pump(3.0)
        k0 = len(c.places)
        c.pump(5.0)
        arr = [p[0] for p in c.places[k0:]]
        gaps = [b - a for a, b in zip(arr, arr[1:], strict=False)]
        mid = statistics.median(gaps)
        print(f"[indi] EQUATORIAL_EOD_COORD pushed every {mid * 1e3:.1f} ms (spread of the "
              f"arrivals {statistics.median(abs(g - mid) for g in gaps) * 1e3:.2f} ms MAD, "
              f"{len(gaps)} intervals); property timestamps look like "
              f"{c.places[-1][1]!r} (whole seconds)")
        shares = []
        rates = [(1800.0, 900.0), (3600.0, 1800.0)]
        for k in range(10):
            old, new = rates[k % 2], rates[(k + 1) % 2]
            n = len(c.places)
            c.pump(0.3)
            while len(c.places) == n:
                c.pump(0.01)
            last = c.places[-1][0]
            time.sleep(random.uniform(0.02, 0.2))
            tc = time.time()
            c.send("Number", "TELESCOPE_TRACK_RATE", {"TRACK_RATE_RA": SIDEREAL - new[0],
                                                      "TRACK_RATE_DE": new[1]})
            n = len(c.places)
            while len(c.places) < n + 1:
                c.pump(0.01)
            t1 = c.places[-1][0]
            before = [p for p in c.places if p[0] <= last][-1]
            d = (c.places[-1][2] - before[2]) * 15 * 3600  # RA arcsec (the place's RA)
            span = t1 - last
            shares.append(((d - old[0] * span) / ((new[0] - old[0]) * span), (t1 - tc) / span))
        print(f"[indi] TELESCOPE_TRACK_RATE sent inside a tick (10 steps): share moved at the "
              f"new rate {statistics.median(s for s, _ in shares):.3f} (median; at once would be "
              f"{statistics.median(i for _, i in shares):.2f}): in force over the whole tick in "
              "which it arrives, from the previous push on")
        c.messages.clear()
        n = len(c.places)
        c.send("Number", "TELESCOPE_TRACK_RATE", {"TRACK_RATE_RA": SIDEREAL - 1800.0,
                                                  "TRACK_RATE_DE": -900.0})
        c.pump(1.2)
        p = c.places[n:]
        de_rate = (p[-1][3] - p[1][3]) * 3600 / (p[-1][0] - p[1][0])
        refused = [m for m in c.messages if "reverse" in m]
        print(f"[indi] a declination rate of the other sign while tracking: the place's dec "
              f"moves at {de_rate:+.0f}″/s afterwards (asked ∓900); driver says "
              f"{refused[0] if refused else 'nothing'!r}")
        c.send("Number", "TELESCOPE_TRACK_RATE", {"TRACK_RATE_RA": SIDEREAL - 1800.0,
                                                  "TRACK_RATE_DE": 0.0})
        c.send("Number", "TELESCOPE_TRACK_RATE", {"TRACK_RATE_RA": SIDEREAL - 1800.0,
                                                  "TRACK_RATE_DE": -900.0})
        n = len(c.places)
        c.pump(1.2)
        p = c.places[n:]
        de_rate2 = (p[-1][3] - p[1][3]) * 3600 / (p[-1][0] - p[1][0])
        print(f"[indi] the same through zero first: dec moves at {de_rate2:+.0f}″/s (the "
              "reversal taken)")
        c.send("Switch", "TELESCOPE_ABORT_MOTION", {"ABORT": "On"})
        c.pump(0.3)
    finally:
        proc.terminate()
        proc.wait(10)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--only", choices=["alpaca", "indi"])
    ap.add_argument("--inner", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if not args.inner:
        cmd = [sys.executable, __file__, "--inner"] + (["--only", args.only] if args.only else [])
        sys.exit(subprocess.call(["unshare", "-n", "sh", "-c", 'ip link set lo up && exec "$0" '
                                  '"$@"', *cmd], env=os.environ))
    if args.only in (None, "alpaca"):
        alpaca()
    if args.only in (None, "indi"):
        indi()


if __name__ == "__main__":
    main()
