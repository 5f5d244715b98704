"""One run of the VSS on a simulator we did not write, in real time; prints what it saw as JSON.

Usage: backend_scenario.py alpaca|indi sky|route|pass|kill OUT_DIR

Four parts, each on its own simulator: ``sky`` (a star: slew, landing, sidereal track,
recorded by `vs record`; `vs run` of a small plan; an offset during a track), ``route``
(the Sun refused; a slew routed round it), ``pass`` (an ISS-like pass stopped mid-pass)
and ``kill`` (the driver killed mid-track). A test module runs two at once (sky and route,
pass and kill: scenario_run.py), and pytest-xdist runs the modules side by side.

Run inside a private network namespace (`unshare -n`, loopback up): indiserver binds
every interface, and the Alpaca simulator is kept there too. The VSS drives the
simulator through `--mount alpaca://…` or `indi://…` (build_server), while an
*independent* client (ASCOM's alpyca for Alpaca, indipyclient for INDI) records every
place the simulator reports, with the time it was read. The tests
(test_mount_backends.py) judge those places against astropy and skyfield; nothing
here decides whether a figure is good.

The site is put where the Sun stands about 50° high now, so that the Sun zone is
real: stars and the satellite pass are chosen away from it, a goto to the Sun must be
refused and a slew past it must go round.
"""

from __future__ import annotations

import asyncio
import json
import logging
import math
import os
import signal
import socket
import subprocess
import sys
import time
import traceback
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))

from synthetic_pass import synthetic_pass_tle  # noqa: E402

BIN = Path(sys.executable).parent
INDI_PORT = 7624
INDI_DEVICE = "Telescope Simulator"
STAR_TRACK_S = 6.0  # the INDI observer asks for a held place: ~8 places in it
ROUTE_OFF_DEG = 40.0  # the route's ends: this far (× 1/cos el in azimuth) either side of the Sun
# (10° outside the 30° zone: the drivers' own slews between the detour's waypoints are what
# must keep out of it, goto_route.py)
OFFSET_ARCSEC = 60.0  # the declination offset applied during a track
OFFSET_GUARD_S = 90.0  # hang guard of the offset's waits (a quiet host: a few seconds)
HELD_S = 1.5  # a place is held when the places reported over this long agree ...
HELD_ARCSEC = 1.0  # ... within this (INDI pushes a change of 0.1 s of RA: 1.5″·cos δ)
PASS_JOIN_S = 35.0  # the followed stretch of the pass begins about this long after the command
PASS_TRACK_S = 8.0  # ... and is stopped this long after the landing check (mid-pass)
PASS_SETTLE_S = 2.0  # the pass is judged from this long after the landing check ...
PASS_PLACES = 20  # ... on at least this many reported places (the track goes on until then)
# where the Alpaca simulator's mount starts: near the south pole, about 30° high over the
# scenario's sites (latitude -30°) whatever their longitude and the time
ALPACA_START_DEC_DEG = -89.0
START_TIMEOUT_S = 120.0  # a loaded host takes long to start a simulator (FastAPI, indiserver)
ASK_QUIET_S = 0.5  # the INDI observer asks for the place again after this long without one
# the Alpaca observer reads the place this often: 5 places a second are 30 on a 6-s track,
# 7 in the offset's 1.5-s hold and dozens on a route or a pass (the checks need 4, 3 and 20);
# each place's time is known to its request's milliseconds whatever the pace, while every
# read costs the simulator two requests (at its old pace, 0.05 s between reads, the observer
# made a third of the simulator's requests; the VSS's own polling makes the rest)
OBSERVE_PERIOD_S = 0.2
REST_COUNT_S = 3.0  # the Alpaca pass: the VSS's requests are counted this long at rest
REST_GUARD_S = 60.0  # hang guard of the wait for the VSS to read at its rest pace


def now_us() -> int:
    return time.time_ns() // 1000


def stop_process(proc: subprocess.Popen, wait_s: float = 10.0) -> None:
    """Terminate a helper process, and kill it if it does not end within `wait_s`."""
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(wait_s)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def free_port() -> int:
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def wait_listening(port: int, what: str) -> None:
    """Wait until something listens on loopback `port` (RuntimeError after START_TIMEOUT_S)."""
    deadline = time.monotonic() + START_TIMEOUT_S
    while time.monotonic() < deadline:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.1)
    raise RuntimeError(f"{what} did not listen on {port}")


class Simulator:
    """The simulator process (started, killed, started again on the same port)."""

    def __init__(self, kind: str, out_dir: Path) -> None:
        self.kind = kind
        self.port = free_port() if kind == "alpaca" else INDI_PORT
        self.out_dir = out_dir
        self.log = open(out_dir / f"{kind}-simulator.log", "ab")  # noqa: SIM115
        self.proc: subprocess.Popen | None = None

    @property
    def url(self) -> str:
        if self.kind == "alpaca":
            return f"alpaca://127.0.0.1:{self.port}/0"
        return f"indi://127.0.0.1:{self.port}/{INDI_DEVICE.replace(' ', '%20')}"

    def start(self) -> None:
        self.launch()
        self.wait_listening()

    def launch(self) -> None:
        """Start the simulator's process (`wait_listening` waits until it serves): its
        start-up (FastAPI's imports: seconds) runs while this process prepares the rest."""
        env = None
        if self.kind == "alpaca":
            # the simulator's ASGI app under uvicorn's own command, as its run_simulator
            # serves it (the configuration named by ASTRA_SIMULATORS_CONFIG, idle keep-alive
            # connections held 300 s) but without a log line per request: a tenth of the
            # CPU of each of the ~60 requests a second the VSS and the observer make
            env = dict(os.environ, ASTRA_SIMULATORS_CONFIG=str(self.alpaca_config()))
            # (alpaca_sim_serve.py: uvicorn's own command, the camera's image library loaded
            # only if a camera image is made)
            cmd = [sys.executable, str(Path(__file__).with_name("alpaca_sim_serve.py")),
                   "alpaca_simulators.main:app", "--host",
                   "127.0.0.1", "--port", str(self.port), "--timeout-keep-alive", "300",
                   "--no-access-log"]
        else:
            cmd = ["indiserver", "-p", str(self.port), "indi_simulator_telescope"]
        self.proc = subprocess.Popen(cmd, stdout=self.log, stderr=self.log, env=env,
                                     start_new_session=True)

    def alpaca_config(self) -> Path:
        """The simulator's configuration (a path): its template, with the mount
        starting at `ALPACA_START_DEC_DEG` instead of the template's +89°, which lies 29°
        below the horizon of the scenario's sites (latitude -30°): the first goto of each part
        (the star's, the pass's) would climb from there, and the VSS waits out its estimate of
        that long slew before the pass's join."""
        import yaml
        from alpaca_simulators.config import CONFIG_DIR

        doc = yaml.safe_load((CONFIG_DIR / "template.yaml").read_text())
        doc["devices"]["telescope"][0]["declination"] = ALPACA_START_DEC_DEG
        path = (self.out_dir / "alpaca-simulator.yaml").resolve()
        path.write_text(yaml.safe_dump(doc))
        return path

    def wait_listening(self) -> None:
        wait_listening(self.port, f"the {self.kind} simulator")

    def kill(self) -> None:
        if self.proc is not None:
            os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait()

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGTERM)
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.kill()


class RequestCounter:
    """A TCP relay between the VSS and the Alpaca simulator that writes down every request
    the VSS makes (time, member), read from the bytes on the wire: how often the VSS asks,
    counted outside the VSS. A process of its own (this script with ``--relay``)."""

    def __init__(self, sim: Simulator) -> None:
        self.port = free_port()
        self.path = sim.out_dir / "vss-requests.txt"
        self.path.touch()
        self.proc = subprocess.Popen(
            [sys.executable, __file__, "--relay", str(self.port), str(sim.port),
             str(self.path)], stdout=sim.log, stderr=sim.log)

    @property
    def url(self) -> str:
        return f"alpaca://127.0.0.1:{self.port}/0"

    def wait_listening(self) -> None:
        wait_listening(self.port, "the request counter")

    def requests(self) -> list[tuple[float, str]]:
        lines = self.path.read_text().split("\n")[:-1]
        return [(float(t), member) for t, member in (line.split() for line in lines)]

    def close(self) -> None:
        stop_process(self.proc)


def relay(port: int, upstream: int, path: Path) -> None:
    """The request counter's process: relay loopback `port` to `upstream`, and append
    "t_s member" for every Alpaca request line that passes towards the simulator."""
    import re

    line = re.compile(rb"(?:GET|PUT) /api/v1/telescope/\d+/(\w+)")

    async def pump(reader, writer, out=None) -> None:
        tail = b""
        try:
            while data := await reader.read(65536):
                if out is not None:
                    # a request line split between two reads is found in the joined tail
                    text = tail + data
                    for m in line.finditer(text):
                        if m.end() > len(tail):
                            out.write(f"{time.time():.6f} {m.group(1).decode()}\n")
                    tail = text[-64:]
                writer.write(data)
                await writer.drain()
        except (ConnectionError, OSError):
            pass
        finally:
            writer.close()

    async def main() -> None:
        with open(path, "a", buffering=1) as out:
            async def serve(reader, writer) -> None:
                try:
                    up_r, up_w = await asyncio.open_connection("127.0.0.1", upstream)
                except OSError:
                    writer.close()
                    return
                await asyncio.gather(pump(reader, up_w, out), pump(up_r, writer))

            server = await asyncio.start_server(serve, "127.0.0.1", port)
            async with server:
                await server.serve_forever()

    asyncio.run(main())


class Observer:
    """An independent client recording every reported place: (t_s, ra_h, dec_deg).

    It runs in a process of its own (this script with ``--observe``), so the time it
    stamps on each place is not delayed by the VSS's work in this process (the GIL); it
    writes one line per place, which `mark` and `since` read back.
    """

    def __init__(self, sim: Simulator) -> None:
        self.sim = sim
        self.path = sim.out_dir / f"observed-{time.time_ns()}.txt"
        self.path.touch()
        self.proc = subprocess.Popen(
            [sys.executable, __file__, "--observe", sim.kind, str(sim.port), str(self.path)],
            stdout=sim.log, stderr=sim.log)

    def _lines(self) -> list[str]:
        lines = self.path.read_text().split("\n")
        return lines[:-1]  # the last is empty, or a line still being written

    def mark(self) -> int:
        return len(self._lines())

    def since(self, k: int) -> list[tuple[float, float, float]]:
        return [tuple(float(x) for x in line.split()) for line in self._lines()[k:]]

    async def wait_places(self, n: int, guard_s: float) -> bool:
        """Wait until `n` places in all have been recorded (False: the hang guard ran out)."""
        deadline = time.monotonic() + guard_s
        while self.mark() < n:
            if time.monotonic() > deadline:
                return False
            await asyncio.sleep(0.1)
        return True

    async def wait_moved_and_held(self, from_s: float, k: int, moved_arcsec: float,
                                  guard_s: float) -> float | None:
        """Wait until a place reported after `from_s` lies `moved_arcsec` from the last one
        before it, and the places since then have stood still (within `HELD_ARCSEC` for
        `HELD_S`): the mount holds a new place. `k` is a mark taken well before the offset
        (places must lie between it and `from_s`). Returns the wall seconds waited, None if
        the hang guard ran out (the test then judges what was seen)."""
        start = time.monotonic()
        while time.monotonic() - start < guard_s:
            await asyncio.sleep(0.2)
            s = np.asarray(self.since(k), float).reshape(-1, 3)
            if not len(s) or not (s[:, 0] < from_s).any():
                continue
            base = s[s[:, 0] < from_s][-1]
            later = s[s[:, 0] >= from_s]
            moved = np.flatnonzero(sky_sep_arcsec(later, base) > moved_arcsec)
            if not len(moved):
                continue
            later = later[moved[0]:]
            still = later[sky_sep_arcsec(later, later[-1]) > HELD_ARCSEC]
            since_s = still[-1, 0] if len(still) else later[0, 0]
            tail = later[later[:, 0] > since_s]
            if len(tail) >= 3 and later[-1, 0] - since_s >= HELD_S:
                return time.monotonic() - start
        return None

    def close(self) -> None:
        stop_process(self.proc)


def observe(kind: str, port: int, path: Path) -> None:
    """The observer process: append every place the simulator reports to `path`."""
    with open(path, "a", buffering=1) as out:
        def put(t: float, ra_h: float, dec_deg: float) -> None:
            out.write(f"{t:.6f} {ra_h!r} {dec_deg!r}\n")

        while True:
            try:
                if kind == "alpaca":
                    _observe_alpaca(port, put)
                else:
                    asyncio.run(_observe_indi(port, put))
            except Exception:  # the simulator killed on purpose: try again
                time.sleep(0.2)


def _observe_alpaca(port: int, put) -> None:
    from alpaca.telescope import Telescope

    tel = Telescope(f"127.0.0.1:{port}", 0)
    while True:
        t0 = time.time()
        ra = tel.RightAscension
        dec = tel.Declination
        t1 = time.time()
        # the simulator answers each with where the mount is when asked (~1 ms apart)
        put((t0 + t1) / 2, float(ra), float(dec))
        time.sleep(OBSERVE_PERIOD_S)


async def _observe_indi(port: int, put) -> None:
    """Every place the INDI server sends, pushed or asked for.

    The driver pushes EQUATORIAL_EOD_COORD only when the place has changed (libindi: by
    more than 0.1 s of RA or 0.1″ of Dec), so a well-held star is silent for seconds. When
    nothing has come for `ASK_QUIET_S`, the observer asks for the property again
    (getProperties with device and name): the driver answers with a definition carrying its
    current place, so a held place is sampled at a steady pace whatever the host's load.
    """
    from indipyclient import IPyClient

    heard = [time.monotonic()]

    class Client(IPyClient):
        async def rxevent(self, event) -> None:
            if (event.devicename == INDI_DEVICE and event.vectorname == "EQUATORIAL_EOD_COORD"
                    and event.eventtype in ("Set", "Define")):
                t = time.time()  # a push (or an answer) describes the moment it is sent
                v = self[INDI_DEVICE]["EQUATORIAL_EOD_COORD"]
                put(t, v.getfloatvalue("RA"), v.getfloatvalue("DEC"))
                heard[0] = time.monotonic()

    client = Client(indihost="127.0.0.1", indiport=port)
    client.debug_verbosity(0)
    run = asyncio.ensure_future(client.asyncrun())
    while not run.done():
        await asyncio.wait({run}, timeout=ASK_QUIET_S / 2)
        if (client.connected and INDI_DEVICE in client
                and time.monotonic() - heard[0] >= ASK_QUIET_S):
            heard[0] = time.monotonic()  # asked: the next ask after another quiet spell
            await client.send_getProperties(INDI_DEVICE, "EQUATORIAL_EOD_COORD")
    run.result()
    raise ConnectionError("the INDI server closed")


def daytime_site(sun_hour_angle_deg: float = -37.5):
    """A site (latitude -30°) where the Sun stands at this hour angle now: by default 2.5 h
    east, about 50° high (180: a night site, the Sun far below the horizon)."""
    from virtualstar.astro import EarthOrientation, SolarSystemBody, load_site
    from virtualstar.astro.mount_frames import observed_to_apparent_radec

    eop = EarthOrientation.from_astropy_iers_data()
    base = load_site().with_overrides(lat_deg=-30.0, lon_deg=0.0, height_m=1500.0)
    t = np.array([now_us()], np.int64)
    from virtualstar.astro import observe_mount_times

    o = observe_mount_times(SolarSystemBody("sun"), t, base, eop)
    ra, _dec = observed_to_apparent_radec(o.az_rad, o.el_rad, t, base, eop)
    from virtualstar.astro.mount_frames import hour_angle_rad

    ha_deg = math.degrees(float(hour_angle_rad(ra, t, base, eop)[0]))
    lon = (sun_hour_angle_deg - ha_deg + 180.0) % 360.0 - 180.0
    return base.with_overrides(lon_deg=lon), eop


def pick_star(site, eop, sun_azel, slew_cost=None):
    """A bright star 35–70° high, ≥ 60° from the Sun, ≥ 20° of hour angle from the meridian:
    the brightest, or with `slew_cost(az_deg, el_deg)` the one of least cost."""
    from catalogs import bright_stars
    from virtualstar.astro import IcrsStar, observe_mount_times
    from virtualstar.astro.mount_frames import hour_angle_rad, observed_to_apparent_radec

    t = np.array([now_us() + 30_000_000], np.int64)
    best = None
    for s in bright_stars():
        if not s.name or s.vmag > 3.5:
            continue
        o = observe_mount_times(IcrsStar.from_catalog(s), t, site, eop)
        el, az = math.degrees(o.el_rad[0]), math.degrees(o.az_rad[0])
        ra, dec = observed_to_apparent_radec(o.az_rad, o.el_rad, t, site, eop)
        ha = math.degrees(float(hour_angle_rad(ra, t, site, eop)[0]))
        if not 35 <= el <= 70 or abs(ha) < 20 or abs(math.degrees(float(dec[0]))) > 75:
            continue
        if sep_deg(az, el, *sun_azel) < 60:
            continue
        key = s.vmag if slew_cost is None else slew_cost(az, el)
        if best is None or key < best[0]:
            best = (key, s)
    return best[1]


def sky_sep_arcsec(places: np.ndarray, ref) -> np.ndarray:
    """Small-angle distance (arcsec) of places (t_s, ra_h, dec_deg) from one such place."""
    d_ra = ((places[:, 1] - ref[1] + 12.0) % 24.0 - 12.0) * 15.0 * np.cos(np.radians(ref[2]))
    return np.hypot(d_ra, places[:, 2] - ref[2]) * 3600.0


def sep_deg(az1, el1, az2, el2) -> float:
    a1, e1, a2, e2 = (math.radians(x) for x in (az1, el1, az2, el2))
    c = math.sin(e1) * math.sin(e2) + math.cos(e1) * math.cos(e2) * math.cos(a1 - a2)
    return math.degrees(math.acos(max(-1.0, min(1.0, c))))


async def wait_op(op, timeout_s: float) -> None:
    await asyncio.wait_for(asyncio.shield(op.done), timeout_s)


def op_doc(op) -> dict:
    return json.loads(json.dumps(op.as_dict(), default=str))


def site_doc(site) -> dict:
    """The site as the truth functions (truth.py) read it."""
    return {k: getattr(site, k) for k in ("lat_deg", "lon_deg", "height_m", "pressure_hpa",
                                          "temperature_c", "humidity", "wavelength_um")}


def sun_azel_now(site, eop) -> tuple[float, float]:
    """The Sun's observed azimuth and elevation now, degrees."""
    from virtualstar.astro import SolarSystemBody, observe_mount_times

    sun = observe_mount_times(SolarSystemBody("sun"), np.array([now_us()], np.int64), site, eop)
    return math.degrees(sun.az_rad[0]), math.degrees(sun.el_rad[0])


class Rig:
    """A simulator, the VSS driving it (`--mount alpaca://…|indi://…`) and the observer."""

    async def open(self, kind: str, site, out_dir: Path, sim: Simulator | None = None,
                   obs: Observer | None = None, mount_url: str | None = None,
                   **build) -> Rig:
        """Start what is not started yet: `sim` may be launched and `obs` observing
        already (their processes start while the caller works out the site)."""
        from virtualstar.server import build_server

        if sim is None:
            sim = Simulator(kind, out_dir)
            sim.launch()
        self.sim = sim
        self.obs = obs or Observer(sim)  # it reads (retrying) once the simulator serves
        sim.wait_listening()
        self.vss = build_server(mount_url=mount_url or self.sim.url, site=site, **build)
        self.url = await self.vss.start("ws://127.0.0.1:0")
        self.t = self.vss.telescope
        await self.t.link.wait_connected(START_TIMEOUT_S)
        await asyncio.sleep(1.0)
        return self

    async def close(self) -> None:
        """Close what `open` got to (the observer, the VSS, the simulator)."""
        if hasattr(self, "obs"):
            self.obs.close()
        if hasattr(self, "vss"):
            await self.vss.close()
        if hasattr(self, "sim"):
            self.sim.stop()


async def scenario(kind: str, part: str, out_dir: Path) -> dict:
    doc: dict = {"kind": kind, "part": part, "errors": [], "steps_s": {}}
    t0 = time.monotonic()
    rig = Rig()
    # the simulator and the observer start first: their processes' start-up (imports,
    # FastAPI, indiserver) runs beside this one's (astropy, the site's Sun)
    rig.sim = sim = Simulator(kind, out_dir)
    sim.launch()
    rig.obs = obs = Observer(sim)
    counter = RequestCounter(sim) if (kind, part) == ("alpaca", "pass") else None
    try:
        # the pass part at night: no Sun zone between the mount and the pass (a detour
        # would only lengthen the test; the sky part proves the routes)
        site, eop = daytime_site(-37.5 if part in ("sky", "route") else 180.0)
        doc["site"] = site_doc(site)
        if counter is not None:
            counter.wait_listening()
        await rig.open(kind, site, out_dir, sim=sim, obs=obs, signals_url="ws://127.0.0.1:0",
                       mount_url=counter and counter.url)
        t, obs, sim, url = rig.t, rig.obs, rig.sim, rig.url
        doc["connected"] = json.loads(json.dumps((await t.status())["backend"], default=str))
        sun_azel = sun_azel_now(site, eop)
        doc["sun_azel_deg"] = sun_azel
        doc["steps_s"]["connected"] = time.monotonic() - t0
        if part == "sky":
            await sky_part(doc, t, url, site, eop, sun_azel, obs, out_dir, t0)
        elif part == "route":
            await route_part(doc, t, sun_azel, obs, t0)
        elif part == "pass":
            await pass_part(doc, t, site, sun_azel, obs, t0, counter)
        else:
            rig.obs = await kill_part(doc, t, sim, obs, t0)
        doc["final_backend"] = json.loads(json.dumps((await t.status())["backend"], default=str))
    except Exception:
        doc["errors"].append(traceback.format_exc())
    finally:
        await rig.close()
        if counter is not None:
            counter.close()
    doc["steps_s"]["end"] = time.monotonic() - t0
    return doc


async def sky_part(doc, t, url, site, eop, sun_azel, obs, out_dir, t0) -> None:
    """A star (landing, track, recorder), `vs run`, an offset during a track."""
    from virtualstar.astro import IcrsStar

    # 1. a star: slew, land, sidereal track (its reports judged against astropy)
    # the star nearest the mount (any bright star proves the same; the slew is a third of
    # this step's wall)
    here = await t.motion.position()
    here_azel = (math.degrees(here.az_rad) % 360.0, math.degrees(here.el_rad))
    star = pick_star(site, eop, sun_azel, slew_cost=lambda az, el: sep_deg(*here_azel, az, el))
    doc["star"] = star.name
    # `vs plan` of step 2 runs beside the star's track (its start-up and search take seconds)
    planning = asyncio.ensure_future(plan_small_program(site, star.name, out_dir))
    # the recorder records the backend's reports like any signal, all through (started
    # first: a loaded host takes seconds to start a process)
    store = out_dir / "store"
    told: list[tuple[int, float, float]] = []  # every report the VSS served as a tick

    def tell(row: dict) -> None:
        if not told or row["t_us"] > told[-1][0]:  # a tick's time only moves forward
            told.append((int(row["t_us"]), row["report.ra_deg"], row["report.dec_deg"]))

    t.link.report_listeners.append(tell)
    rec = await asyncio.create_subprocess_exec(
        str(BIN / "vs"), "record", t.signals.url, "report.ra_deg", "report.dec_deg",
        "rate.axis1_arcsec_s", "error.sky_arcsec", "--rate", "50", "--duration", "600",
        "--store", f"parquet:{store}",
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE)
    # the track begins once the recorder streams (a loaded host takes seconds to start it)
    await wait_streaming(t.signals, rec, START_TIMEOUT_S)
    op = await t.follow_target(IcrsStar.from_catalog(star), star.name,
                               duration_s=STAR_TRACK_S)
    await op.begun
    k = obs.mark()
    await wait_op(op, STAR_TRACK_S + 60)
    rec.send_signal(signal.SIGINT)  # Ctrl-C: the recorder closes its store and exits
    _out, rec_err = await asyncio.wait_for(rec.communicate(), 60)
    t.link.report_listeners.remove(tell)
    doc["star_op"] = op_doc(op)
    doc["star_samples"] = obs.since(k)
    # the store is read back (`vs data query`) beside the steps that follow
    q = await asyncio.create_subprocess_exec(
        str(BIN / "vs"), "data", "query", str(store), "--to", "end", "--json",
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE)
    querying = asyncio.ensure_future(q.communicate())
    doc["recorded"] = {"record_exit": rec.returncode, "record_stderr": rec_err.decode()[-1500:],
                       "report_period_s": t.link.stats.period_s(), "told": told}

    doc["steps_s"]["star"] = time.monotonic() - t0
    # 2. vs run of a small plan: one block of the same star, planned and run by the CLI
    doc["run"] = await run_small_plan(url, await planning, out_dir)
    doc["steps_s"]["run"] = time.monotonic() - t0
    q_out, q_err = await querying
    doc["recorded"].update({"query_exit": q.returncode, "query_stderr": q_err.decode()[-1500:],
                            "data": json.loads(q_out) if q.returncode == 0 else None})

    # 2b. a PWI4-style offset during a track: the rate loop follows the offset path
    k = obs.mark()  # from the slew on
    op = await t.follow_target(IcrsStar.from_catalog(star), star.name, duration_s=None)
    await op.begun
    # on the star before: a second, and a few places of the held star (the INDI observer
    # asks for them)
    n = obs.mark()
    await asyncio.sleep(1.0)
    await obs.wait_places(n + 3, OFFSET_GUARD_S)
    answer = await t.steering.offset("dec", "add", arcsec=OFFSET_ARCSEC)
    # then until the mount holds the new place, however long a loaded host takes
    held_after_s = await obs.wait_moved_and_held(answer["from_us"] / 1e6, k,
                                                 OFFSET_ARCSEC / 2, OFFSET_GUARD_S)
    doc["offset"] = {"answer": json.loads(json.dumps(answer, default=str)),
                     "samples": obs.since(k), "arcsec": OFFSET_ARCSEC,
                     "held_after_s": held_after_s, "op_before_stop": op_doc(op)}
    await t.stop()
    doc["steps_s"]["offset"] = time.monotonic() - t0


async def route_part(doc, t, sun_azel, obs, t0) -> None:
    """The Sun refused, and a slew routed round its zone."""
    from virtualstar.astro import SolarSystemBody

    # 3. the Sun: refused before anything moves
    try:
        await t.follow_target(SolarSystemBody("sun"), "Sun", duration_s=10)
        doc["sun_refusal"] = None
    except Exception as exc:
        doc["sun_refusal"] = {"code": getattr(exc, "code", type(exc).__name__),
                              "message": str(exc)}

    # 4. a slew whose straight path would cross the Sun zone goes round it
    # on either side of the Sun in azimuth, `ROUTE_OFF_DEG` of azimuth × cos el from it, both
    # on the same side of north (the VSS reports azimuths 0..360°): the straight way passes
    # the Sun, and the detour's gotos run 30-odd degrees from it
    ends = route_ends(sun_azel)
    off = ROUTE_OFF_DEG / math.cos(math.radians(ends[0][1]))
    if not off < sun_azel[0] < 360.0 - off:
        doc["errors"].append(f"the Sun's azimuth {sun_azel[0]:.1f}° leaves no room")
    a, b = ends
    # the first slew puts the mount at one end without passing the Sun (the end on the
    # mount's side of it): only the second must go round
    here_az = math.degrees((await t.motion.position()).az_rad) % 360.0
    if (here_az - sun_azel[0]) * (a[0] - sun_azel[0]) < 0:
        a, b = b, a
    op = await t.slew_altaz(*a)
    await wait_op(op, 300)
    doc["route_first"] = op_doc(op)
    k = obs.mark()
    op = await t.slew_altaz(*b)
    await wait_op(op, 300)
    doc["route_op"] = op_doc(op)
    doc["route_samples"] = obs.since(k)
    doc["route_ends"] = [a, b]
    doc["steps_s"]["route"] = time.monotonic() - t0


def route_ends(sun_azel) -> tuple[tuple[float, float], tuple[float, float]]:
    """The ends (az, el deg) of the slew past the Sun: either side of it in azimuth,
    `ROUTE_OFF_DEG` × 1/cos el from it, 35° high (25° when the Sun is lower than 30°)."""
    el = 35.0 if sun_azel[1] > 30 else 25.0
    off = ROUTE_OFF_DEG / math.cos(math.radians(el))
    return ((sun_azel[0] - off) % 360.0, el), ((sun_azel[0] + off) % 360.0, el)


async def pass_part(doc, t, site, sun_azel, obs, t0, counter=None) -> None:
    """An ISS-like pass stopped mid-pass (with `counter`: the VSS's requests counted while
    it follows and at rest after the stop)."""
    from virtualstar.astro import Satellite

    # 5. a satellite pass (ISS-like, culminating away from the Sun), stopped mid-pass,
    # timed so that the stretch the mount follows begins ~PASS_JOIN_S from now
    name, l1, l2, culm_s = timed_pass(site, sun_azel[0],
                                      doc["connected"]["capabilities"]["geometry"])
    doc["tle"] = [name, l1, l2]
    doc["culmination_s"] = culm_s
    op = await t.track_satellite(Satellite.from_tle(l1, l2, name))
    await op.begun
    k = obs.mark()
    tracking_since = None
    # followed for PASS_TRACK_S, and on until the observer has PASS_PLACES places of the
    # followed stretch (a loaded host may deliver fewer a second), within the pass
    while not op.done.done() and time.time() < culm_s + 150:
        if op.phase.label == "tracking" and tracking_since is None:
            tracking_since = time.time()
        if tracking_since is not None and time.time() > tracking_since + PASS_TRACK_S:
            judged_from_s = op.info.get("tracking_from_us", 0) / 1e6 + PASS_SETTLE_S
            if sum(x[0] >= judged_from_s for x in obs.since(k)) >= PASS_PLACES:
                break
        await asyncio.sleep(0.2)
    doc["pass_op_before_stop"] = op_doc(op)
    stop_at = time.time()
    doc["stop_result"] = await t.stop()
    doc["stop_answered_s"] = time.time() - stop_at
    doc["stop_sent_s"] = stop_at
    # the mount must stay at rest: the observer keeps reading, 4 s and at least 6 places
    rest_from = obs.mark()
    rest = asyncio.ensure_future(count_at_rest(t, counter)) if counter else None
    await asyncio.sleep(4.0)
    await obs.wait_places(rest_from + 6, 60.0)
    if rest is not None:
        doc["requests"] = {"rest": await rest, "all": counter.requests(),
                           "rest_poll_s": t.link.pace.rest_s, "poll_s": t.link.pace.fast_s}
    doc["pass_op"] = op_doc(op)
    doc["pass_samples"] = obs.since(k)
    doc["steps_s"]["pass"] = time.monotonic() - t0


async def count_at_rest(t, counter: RequestCounter) -> list[float]:
    """Once the VSS says it reads at its rest pace (status), the window [from, to] (s) of
    `REST_COUNT_S` in which the counter's requests are judged."""
    deadline = time.monotonic() + REST_GUARD_S
    while t.link.describe()["poll_period_s"] != t.link.pace.rest_s:
        if time.monotonic() > deadline:
            return []
        await asyncio.sleep(0.05)
    start = time.time()
    await asyncio.sleep(REST_COUNT_S)
    return [start, time.time()]


async def kill_part(doc, t, sim, obs, t0):
    """The driver killed mid-track (returns the observer of the restarted simulator)."""
    from virtualstar.astro import IcrsStar

    # 6. the driver killed mid-track: a fault, the mount told to stop, nothing resumed.
    # The track follows the place the mount points at (no slew first: the test is short)
    from virtualstar.astro.equatorial import jnow_to_icrs

    v = await t.link.read(["axis1_position", "axis2_position"])
    here_icrs = jnow_to_icrs(math.degrees(v["axis1_position"]) % 360.0,
                             math.degrees(v["axis2_position"]), now_us())
    op = await t.follow_target(IcrsStar(*here_icrs), "the place it points at",
                               duration_s=None)
    await op.begun
    await asyncio.sleep(3.0)
    calls_before = len(t.link.calls) and t.link.calls[-1].seq
    killed = time.time()
    sim.kill()
    try:
        await wait_op(op, 30)
    except TimeoutError:
        doc["errors"].append("the operation did not end within 30 s of the kill")
    doc["kill_op"] = op_doc(op)
    doc["kill_fault_after_s"] = time.time() - killed
    # what the VSS sent between the kill and the fault (a command already on its way,
    # and the stop), and after the fault
    doc["calls_after_kill"] = [c.role for c in t.link.calls if c.seq > calls_before]
    calls_before = len(t.link.calls) and t.link.calls[-1].seq
    obs.close()
    sim.launch()
    obs = Observer(sim)  # its start-up beside the simulator's (it reads once that serves)
    sim.wait_listening()
    await t.link.wait_connected(START_TIMEOUT_S)
    # 5 s from the reconnection in which nothing may be sent; the places of its last 3 s
    await asyncio.sleep(2.0)
    k = obs.mark()
    await asyncio.sleep(3.0)
    doc["after_restart"] = {"status": json.loads(json.dumps(
        (await t.status())["backend"], default=str)), "samples": obs.since(k),
        "operation": op_doc(t.op) if t.op else None,
        "calls": [c.role for c in t.link.calls if c.seq > calls_before]}
    doc["steps_s"]["kill"] = time.monotonic() - t0
    return obs


def timed_pass(site, sun_az_deg: float, geometry: str) -> tuple[str, str, str, float]:
    """An ISS-like pass whose followed stretch begins about `PASS_JOIN_S` from now.

    A fork or alt-az mount joins as soon as it can: the pass culminates then. A German
    mount follows one side of the meridian only (the VSS picks the longest such stretch),
    and a pass culminating 70° high crosses the meridian some 20° from culmination: the
    pass is shifted so that the crossing comes `PASS_JOIN_S` from now (the stretch after
    it, the longer, is followed, still at about 1°/s).
    """
    from virtualstar.astro import EarthOrientation, Satellite, observe_mount_times
    from virtualstar.astro.mount_frames import hour_angle_rad, observed_to_apparent_radec

    culm_s = time.time() + PASS_JOIN_S + 5.0
    name, l1, l2 = synthetic_pass_tle(site.lat_deg, site.lon_deg, site.height_m, culm_s,
                                      away_from_az_deg=sun_az_deg)
    if geometry != "german":
        return name, l1, l2, culm_s
    eop = EarthOrientation.from_astropy_iers_data()
    t = np.arange(int((culm_s - 90) * 1e6), int((culm_s + 90) * 1e6), 500_000, dtype=np.int64)
    o = observe_mount_times(Satellite.from_tle(l1, l2, name), t, site, eop)
    ra, _dec = observed_to_apparent_radec(o.az_rad, o.el_rad, t, site, eop)
    ha = hour_angle_rad(ra, t, site, eop)
    up = o.el_rad > math.radians(20.0)
    flips = np.flatnonzero((np.sign(ha[1:]) != np.sign(ha[:-1])) & up[1:])
    if not len(flips):
        return name, l1, l2, culm_s
    t_m = t[flips[0] + 1] / 1e6
    # where the crossing lies relative to the culmination, when it should come
    culm_s += time.time() + PASS_JOIN_S - t_m
    name, l1, l2 = synthetic_pass_tle(site.lat_deg, site.lon_deg, site.height_m, culm_s,
                                      away_from_az_deg=sun_az_deg)
    return name, l1, l2, culm_s


async def plan_small_program(site, star: str, out_dir: Path) -> dict:
    """`vs plan` a one-star program over the next minutes: {"plan_exit", "stderr"}."""
    from virtualstar.astro import iso_utc

    site_file = out_dir / "site.toml"
    site_file.write_text(
        f"[site]\nlat_deg = {site.lat_deg}\nlon_deg = {site.lon_deg}\n"
        f"height_m = {site.height_m}\npressure_hpa = {site.pressure_hpa}\n"
        f"temperature_c = {site.temperature_c}\nhumidity = {site.humidity}\n")
    program = out_dir / "program.toml"
    program.write_text(
        '[program]\nname = "backend test"\n\n[defaults]\nmin_el_deg = 20\n'
        "sun_max_el_deg = 90\nmoon_min_sep_deg = 0\n\n"
        f'[[target]]\nstar = "{star}"\nduration_s = 8\n')
    start = now_us() + 3_000_000
    p = await asyncio.create_subprocess_exec(
        str(BIN / "vs"), "plan", str(program), "--from", iso_utc(start), "--to",
        iso_utc(start + 240_000_000), "--site-file", str(site_file), "-o",
        str(out_dir / "plan.json"), stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE)
    _out, err = await p.communicate()
    return {"plan_exit": p.returncode, "stderr": err.decode()[-2000:]}


async def run_small_plan(url: str, planned: dict, out_dir: Path) -> dict:
    """`vs run` the plan of `plan_small_program` on this VSS."""
    from virtualstar.astro import iso_utc

    if planned["plan_exit"] != 0:
        return planned
    plan = out_dir / "plan.json"
    run = out_dir / "run.json"
    # the planner times the first slew from its park place, and planned while the mount
    # tracked the star (it cannot know the mount is on the star already): the block is
    # moved to begin soon, 12 s from now (`vs run`'s start-up on a loaded host)
    doc_plan = json.loads(plan.read_text())
    for block in doc_plan["blocks"][:1]:
        shift = now_us() + 12_000_000 - block["start_us"]
        for key in ("start", "end"):
            block[f"{key}_us"] += shift
            block[f"{key}_utc"] = iso_utc(block[f"{key}_us"])
    plan.write_text(json.dumps(doc_plan))
    p = await asyncio.create_subprocess_exec(
        str(BIN / "vs"), "run", str(plan), "--server", url, "-o", str(run),
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE)
    out, err = await asyncio.wait_for(p.communicate(), 400)
    doc = {"plan_exit": 0, "run_exit": p.returncode, "stderr": err.decode()[-2000:],
           "plan": json.loads(plan.read_text())}
    if run.exists():
        doc["record"] = json.loads(run.read_text())
    return doc


async def wait_streaming(signals, rec, guard_s: float) -> None:
    """Wait until a client (the recorder `rec`) streams the backend's signals."""
    deadline = time.monotonic() + guard_s
    while not signals.endpoint.service.groups:
        if rec.returncode is not None or time.monotonic() > deadline:
            raise RuntimeError(f"vs record did not stream within {guard_s:.0f} s "
                               f"(exit {rec.returncode})")
        await asyncio.sleep(0.05)


def log_vss_to(path: Path) -> None:
    """Log the VSS at DEBUG to `path`: the rate loop's every cycle, for a post-mortem."""
    log = logging.FileHandler(path)
    log.setFormatter(logging.Formatter("%(created).3f %(name)s %(levelname)s %(message)s"))
    logging.getLogger("virtualstar").addHandler(log)
    logging.getLogger("virtualstar").setLevel(logging.DEBUG)


def main() -> None:
    if sys.argv[1] == "--observe":
        observe(sys.argv[2], int(sys.argv[3]), Path(sys.argv[4]))
        return
    if sys.argv[1] == "--relay":
        relay(int(sys.argv[2]), int(sys.argv[3]), Path(sys.argv[4]))
        return
    kind, part, out_dir = sys.argv[1], sys.argv[2], Path(sys.argv[3])
    out_dir.mkdir(parents=True, exist_ok=True)
    log_vss_to(out_dir / "vss.log")
    doc = asyncio.run(scenario(kind, part, out_dir))
    text = json.dumps(doc, default=str)
    (out_dir / "scenario.json").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
