"""`vs-indi`: an INDI telescope driver, run by indiserver, that drives the VirtualStar Server.

    indiserver vs-indi            # the VSS from $VS_SERVER (default ws://127.0.0.1:8740),
                                  # its operator password from $VS_PASSWORD

Standard telescope properties map onto VSS commands (docs/alpaca-indi.md):
EQUATORIAL_EOD_COORD (JNow) with ON_COORD_SET TRACK/SLEW → `slew` (SLEW then `stop`s
tracking), TELESCOPE_ABORT_MOTION → `stop`, TELESCOPE_PARK → `park`,
TELESCOPE_TRACK_STATE → `track` of where it points / `stop`, TELESCOPE_MOTION_NS/WE →
`move`, TELESCOPE_TIMED_GUIDE_NS/WE → `guide`, HORIZONTAL_COORD → `slew` to az/el,
SAT_TLE_TEXT + SAT_TRACKING_STAT → `track` of the TLE. States stay true to the
operation: a coordinate property is Busy from the command until the VSS says the
mount arrived (Ok) or failed (Alert); the periodic status poll updates values but
never overwrites Busy.
"""

from __future__ import annotations

import asyncio
import logging
import math
import os
import sys
from typing import Any

from virtualstar.astro.equatorial import icrs_to_jnow, jnow_to_icrs
from virtualstar.vss_client import (
    PASSWORD_ENV_VAR,
    ServerUnavailable,
    VssClient,
    VssRequestError,
    default_server_url,
)

from .protocol import ALERT, BUSY, IDLE, OK, Element, Reader, Request, Vector, message_xml

__all__ = ["IndiTelescope", "main"]

log = logging.getLogger("virtualstar.indi")

DEVICE = "VirtualStar"
POLL_S = 1.0
MOTION_RATE_DEG_S = 1.0  # TELESCOPE_MOTION_* hand-pad rate
GUIDE_RATE_ARCSEC_S = 0.5 * 15.041067
MOVING = frozenset({"starting", "preparing", "slewing", "joining", "settling", "waiting",
                    "pass planned"})
ENDED = frozenset({"done", "failed", "aborted"})
MAIN, MOTION, SITE, SAT = "Main Control", "Motion Control", "Site Management", "Satellite"


def _n(name: str, label: str, fmt: str, lo: float, hi: float, value: float = 0.0) -> Element:
    return Element(name, label, value, fmt, lo, hi, 0.0)


def _s(name: str, label: str, on: bool = False) -> Element:
    return Element(name, label, on)


def properties() -> list[Vector]:
    d = DEVICE
    return [
        Vector(d, "CONNECTION", "Switch", "Connection", MAIN,
               [_s("CONNECT", "Connect"), _s("DISCONNECT", "Disconnect", True)]),
        Vector(d, "DRIVER_INFO", "Text", "Driver Info", "General Info",
               [Element("DRIVER_NAME", "Name", "VirtualStar"),
                Element("DRIVER_EXEC", "Exec", "vs-indi"),
                Element("DRIVER_VERSION", "Version", "1.0"),
                Element("DRIVER_INTERFACE", "Interface", "5")], perm="ro"),
        Vector(d, "EQUATORIAL_EOD_COORD", "Number", "Eq. Coordinates", MAIN,
               [_n("RA", "RA (hh:mm:ss)", "%010.6m", 0, 24), _n("DEC", "DEC (dd:mm:ss)",
                                                                  "%010.6m", -90, 90)]),
        Vector(d, "ON_COORD_SET", "Switch", "On Set", MAIN,
               [_s("TRACK", "Track", True), _s("SLEW", "Slew"), _s("SYNC", "Sync")]),
        Vector(d, "HORIZONTAL_COORD", "Number", "Horizontal Coordinates", MAIN,
               [_n("AZ", "AZ D:M:S", "%010.6m", 0, 360), _n("ALT", "Alt D:M:S", "%010.6m",
                                                              -90, 90)]),
        Vector(d, "TELESCOPE_ABORT_MOTION", "Switch", "Abort Motion", MAIN,
               [_s("ABORT", "Abort")], rule="AtMostOne"),
        Vector(d, "TELESCOPE_PARK", "Switch", "Parking", MAIN,
               [_s("PARK", "Park(ed)"), _s("UNPARK", "UnPark(ed)", True)]),
        Vector(d, "TELESCOPE_TRACK_STATE", "Switch", "Tracking", MAIN,
               [_s("TRACK_ON", "On"), _s("TRACK_OFF", "Off", True)]),
        Vector(d, "TELESCOPE_MOTION_NS", "Switch", "Motion N/S", MOTION,
               [_s("MOTION_NORTH", "North"), _s("MOTION_SOUTH", "South")], rule="AtMostOne"),
        Vector(d, "TELESCOPE_MOTION_WE", "Switch", "Motion W/E", MOTION,
               [_s("MOTION_WEST", "West"), _s("MOTION_EAST", "East")], rule="AtMostOne"),
        Vector(d, "TELESCOPE_TIMED_GUIDE_NS", "Number", "Guide N/S", MOTION,
               [_n("TIMED_GUIDE_N", "North (ms)", "%.f", 0, 60000),
                _n("TIMED_GUIDE_S", "South (ms)", "%.f", 0, 60000)]),
        Vector(d, "TELESCOPE_TIMED_GUIDE_WE", "Number", "Guide W/E", MOTION,
               [_n("TIMED_GUIDE_W", "West (ms)", "%.f", 0, 60000),
                _n("TIMED_GUIDE_E", "East (ms)", "%.f", 0, 60000)]),
        Vector(d, "GEOGRAPHIC_COORD", "Number", "Location", SITE,
               [_n("LAT", "Lat (dd:mm:ss)", "%010.6m", -90, 90),
                _n("LONG", "Lon (dd:mm:ss)", "%010.6m", 0, 360),
                _n("ELEV", "Elevation (m)", "%g", -200, 10000)], perm="ro"),
        Vector(d, "TIME_UTC", "Text", "UTC", SITE,
               [Element("UTC", "UTC Time", ""), Element("OFFSET", "UTC Offset", "0")], perm="ro"),
        Vector(d, "TELESCOPE_INFO", "Number", "Scope Properties", "Options",
               [_n("TELESCOPE_APERTURE", "Aperture (mm)", "%g", 10, 5000),
                _n("TELESCOPE_FOCAL_LENGTH", "Focal Length (mm)", "%g", 10, 50000),
                _n("GUIDER_APERTURE", "Guider Aperture (mm)", "%g", 10, 5000),
                _n("GUIDER_FOCAL_LENGTH", "Guider Focal Length (mm)", "%g", 10, 50000)]),
        Vector(d, "SAT_TLE_TEXT", "Text", "Orbit Params", SAT, [Element("TLE", "TLE", "")]),
        Vector(d, "SAT_PASS_WINDOW", "Text", "Pass Window", SAT,
               [Element("SAT_PASS_WIN_START", "Start", ""),
                Element("SAT_PASS_WIN_END", "End", "")]),
        Vector(d, "SAT_TRACKING_STAT", "Switch", "Sat tracking", SAT,
               [_s("SAT_TRACK", "Track"), _s("SAT_HALT", "Halt", True)]),
    ]


class IndiTelescope:
    """The driver's state and handlers; `out(text)` writes XML to indiserver."""

    def __init__(self, out, url: str, password: str | None) -> None:
        self.out = out
        self.url = url
        self.password = password
        self.props = {v.name: v for v in properties()}
        self.vss: VssClient | None = None
        self.busy: dict[str, int | None] = {}  # property → VSS operation it waits for
        self.tasks: set[asyncio.Task] = set()

    # ------------------------------------------------------------------ output
    def send(self, name: str, message: str | None = None) -> None:
        self.out(self.props[name].set_xml(message))

    def say(self, text: str) -> None:
        self.out(message_xml(DEVICE, text))

    def set_state(self, name: str, state: str, message: str | None = None) -> None:
        self.props[name].state = state
        if state != BUSY:
            self.busy.pop(name, None)
        self.send(name, message)

    # ------------------------------------------------------------------ input
    async def handle(self, req: Request) -> None:
        if req.tag == "getProperties":
            if req.device in (None, DEVICE):
                for v in self.props.values():
                    if req.name in (None, v.name):
                        self.out(v.define_xml())
            return
        if req.device != DEVICE or req.name not in self.props:
            return
        prop = self.props[req.name]
        if prop.perm == "ro":
            self.set_state(prop.name, ALERT, f"{prop.name} is read-only")
            return
        handler = getattr(self, f"on_{prop.name.lower()}", None)
        if req.name != "CONNECTION" and self.vss is None:
            self.set_state(prop.name, ALERT, "not connected: switch CONNECTION to CONNECT")
            return
        try:
            if handler is None:
                self._store(prop, req.members)
                self.set_state(prop.name, OK)
            else:
                await handler(prop, req.members)
        except VssRequestError as exc:
            self.set_state(prop.name, ALERT, f"{exc.message} [VSS {exc.code}]")
        except (ServerUnavailable, TimeoutError) as exc:
            self.set_state(prop.name, ALERT, f"the VirtualStar Server does not answer: {exc}")
        except ValueError as exc:
            self.set_state(prop.name, ALERT, str(exc))

    @staticmethod
    def _store(prop: Vector, members: dict[str, str]) -> None:
        for name, text in members.items():
            if name not in prop.index:
                raise ValueError(f"{prop.name} has no member {name}")
            el = prop[name]
            if prop.kind == "Number":
                el.value = _number(prop.name, name, text)
            elif prop.kind == "Switch":
                el.value = text.strip() == "On"
            else:
                el.value = text
        if prop.kind == "Switch" and prop.rule == "OneOfMany":
            on = [n for n, t in members.items() if t.strip() == "On"]
            if on:
                for e in prop.elements:
                    e.value = e.name == on[-1]

    async def request(self, cmd: str, params: dict[str, Any] | None = None,
                      timeout_s: float | None = 30.0) -> Any:
        assert self.vss is not None
        return await self.vss.request(cmd, params or {}, timeout_s)

    def begin(self, prop_name: str, cmd: str, params: dict[str, Any]) -> None:
        """Send an operation; the property is Busy until it lands (Ok) or fails (Alert)."""
        self.set_state(prop_name, BUSY)
        self.busy[prop_name] = None

        async def run() -> None:
            try:
                op = await self.request(cmd, params, None)
                self.busy[prop_name] = op.get("id") if isinstance(op, dict) else None
            except VssRequestError as exc:
                if prop_name in self.busy:
                    self.set_state(prop_name, ALERT, f"{exc.message} [VSS {exc.code}]")
                return
            except ServerUnavailable as exc:
                self.set_state(prop_name, ALERT, str(exc))
                return
            if prop_name in self.busy:
                self.set_state(prop_name, OK)

        task = asyncio.get_running_loop().create_task(run())
        self.tasks.add(task)
        task.add_done_callback(self.tasks.discard)

    # ------------------------------------------------------------------ handlers
    async def on_connection(self, prop: Vector, members: dict[str, str]) -> None:
        self._store(prop, members)
        if prop["CONNECT"].value:
            if self.vss is None:
                self.vss = await VssClient.connect(self.url, reconnect=True,
                                                   password=self.password)
                if self.vss.role != "operator":
                    await self.vss.close()
                    self.vss = None
                    prop["CONNECT"].value, prop["DISCONNECT"].value = False, True
                    raise ValueError(f"{self.url} gave the observer role: set $VS_PASSWORD to "
                                     "the operator password")
            self.set_state("CONNECTION", OK, f"connected to {self.url}")
            await self.poll()
        else:
            if self.vss is not None:
                await self.vss.close()
                self.vss = None
            self.set_state("CONNECTION", IDLE, "disconnected")

    async def on_equatorial_eod_coord(self, prop: Vector, members: dict[str, str]) -> None:
        ra_h = _number(prop.name, "RA", members.get("RA", ""))
        dec = _number(prop.name, "DEC", members.get("DEC", ""))
        if not (0 <= ra_h < 24 and -90 <= dec <= 90):
            raise ValueError(f"RA {ra_h:g} h, DEC {dec:g}°: expected 0 <= RA < 24, -90..90")
        mode = next(e.name for e in self.props["ON_COORD_SET"].elements if e.value)
        if mode == "SYNC":
            raise ValueError("SYNC is not supported: VirtualStar corrects pointing with a fitted "
                             "pointing model (vs pointing-run), not with syncs")
        st = await self.request("status")
        ra, dec_icrs = jnow_to_icrs(ra_h * 15.0, dec, st["mount_time_us"])
        self.begin(prop.name, "slew", {"ra_deg": ra, "dec_deg": dec_icrs})
        if mode == "SLEW":
            self._after(prop.name, self.request("stop"))

    def _after(self, prop_name: str, coro) -> None:
        async def run() -> None:
            while prop_name in self.busy:
                await asyncio.sleep(0.05)
            if self.props[prop_name].state == OK:
                await coro
            else:
                coro.close()

        task = asyncio.get_running_loop().create_task(run())
        self.tasks.add(task)
        task.add_done_callback(self.tasks.discard)

    async def on_horizontal_coord(self, prop: Vector, members: dict[str, str]) -> None:
        az = _number(prop.name, "AZ", members.get("AZ", ""))
        alt = _number(prop.name, "ALT", members.get("ALT", ""))
        if not (0 <= az < 360 and -90 <= alt <= 90):
            raise ValueError(f"AZ {az:g}, ALT {alt:g}: expected 0 <= AZ < 360, -90..90")
        self.begin(prop.name, "slew", {"az_deg": az, "el_deg": alt})

    async def on_telescope_abort_motion(self, prop: Vector, members: dict[str, str]) -> None:
        await self.request("stop")
        for name in list(self.busy):
            self.set_state(name, ALERT, "aborted")
        for name in ("TELESCOPE_MOTION_NS", "TELESCOPE_MOTION_WE"):
            for e in self.props[name].elements:
                e.value = False
            self.set_state(name, IDLE)
        self.set_state(prop.name, OK, "motion aborted")

    async def on_telescope_park(self, prop: Vector, members: dict[str, str]) -> None:
        self._store(prop, members)
        if prop["PARK"].value:
            self.begin(prop.name, "park", {"wait": True})
        else:
            self.set_state(prop.name, OK, "unparked")

    async def on_telescope_track_state(self, prop: Vector, members: dict[str, str]) -> None:
        self._store(prop, members)
        if prop["TRACK_ON"].value:
            st = await self.request("status")
            self.begin(prop.name, "track", dict(st["radec"]))
        else:
            await self.request("stop")
            self.set_state(prop.name, OK)

    async def _motion(self, prop: Vector, members: dict[str, str]) -> None:
        self._store(prop, members)
        ns, we = self.props["TELESCOPE_MOTION_NS"], self.props["TELESCOPE_MOTION_WE"]
        el_rate = MOTION_RATE_DEG_S * (ns["MOTION_NORTH"].value - ns["MOTION_SOUTH"].value)
        az_rate = MOTION_RATE_DEG_S * (we["MOTION_EAST"].value - we["MOTION_WEST"].value)
        if az_rate == 0 and el_rate == 0:
            await self.request("stop")
            self.set_state(prop.name, IDLE)
            return
        await self.request("move", {"az_rate_deg_s": az_rate, "el_rate_deg_s": el_rate})
        self.set_state(prop.name, BUSY)

    on_telescope_motion_ns = _motion
    on_telescope_motion_we = _motion

    async def _guide(self, prop: Vector, members: dict[str, str]) -> None:
        self._store(prop, members)
        values = {n: float(v) for n, v in prop.values().items()}
        north = values.get("TIMED_GUIDE_N", 0.0) - values.get("TIMED_GUIDE_S", 0.0)
        east = values.get("TIMED_GUIDE_E", 0.0) - values.get("TIMED_GUIDE_W", 0.0)
        for e in prop.elements:
            e.value = 0.0
        ms = north if prop.name.endswith("NS") else east
        if ms == 0:
            self.set_state(prop.name, OK)
            return
        size = GUIDE_RATE_ARCSEC_S * abs(ms) / 1000.0 * math.copysign(1.0, ms)
        key = "north_arcsec" if prop.name.endswith("NS") else "east_arcsec"
        pulse = await self.request("guide", {key: size, "rate_arcsec_s": GUIDE_RATE_ARCSEC_S})
        self.set_state(prop.name, BUSY)
        self.busy[prop.name] = pulse["id"]
        self._pulse_end = getattr(self, "_pulse_end", {})
        self._pulse_end[prop.name] = pulse["end_us"]

    on_telescope_timed_guide_ns = _guide
    on_telescope_timed_guide_we = _guide

    async def on_sat_tracking_stat(self, prop: Vector, members: dict[str, str]) -> None:
        self._store(prop, members)
        if prop["SAT_TRACK"].value:
            tle = str(self.props["SAT_TLE_TEXT"]["TLE"].value)
            if not tle.strip():
                raise ValueError("set SAT_TLE_TEXT (the TLE: name line and two element lines) "
                                 "first")
            self.begin(prop.name, "track", {"tle": tle, "wait": True})
        else:
            await self.request("stop")
            self.set_state(prop.name, OK)

    # ------------------------------------------------------------------ status poll
    async def poll(self) -> None:
        """Refresh the values from the VSS; never turn a Busy property Ok by itself."""
        if self.vss is None:
            return
        st = await self.request("status")
        if "mount_time_us" not in st:
            return
        t_us = st["mount_time_us"]
        op = st.get("operation") or {}
        ra, dec = icrs_to_jnow(st["radec"]["ra_deg"], st["radec"]["dec_deg"], t_us)
        eq = self.props["EQUATORIAL_EOD_COORD"]
        eq["RA"].value, eq["DEC"].value = ra / 15.0, dec
        hz = self.props["HORIZONTAL_COORD"]
        hz["AZ"].value, hz["ALT"].value = st["observed"]["az_deg"] % 360.0, st["observed"]["el_deg"]
        for name in ("EQUATORIAL_EOD_COORD", "HORIZONTAL_COORD"):
            if name not in self.busy and self.props[name].state == BUSY:
                self.props[name].state = OK
            self.send(name)
        tracking = (op.get("kind") in ("slew", "track", "track_satellite")
                    and op.get("phase") not in ENDED and not op.get("info", {}).get("fixed"))
        ts = self.props["TELESCOPE_TRACK_STATE"]
        ts["TRACK_ON"].value, ts["TRACK_OFF"].value = tracking, not tracking
        if "TELESCOPE_TRACK_STATE" not in self.busy:
            ts.state = BUSY if tracking else IDLE
        self.send("TELESCOPE_TRACK_STATE")
        for name, end in list(getattr(self, "_pulse_end", {}).items()):
            if t_us >= end:
                del self._pulse_end[name]
                self.set_state(name, OK)
        site = st["site"]
        geo = self.props["GEOGRAPHIC_COORD"]
        geo["LAT"].value, geo["LONG"].value = site["lat_deg"], site["lon_deg"] % 360.0
        geo["ELEV"].value = site["height_m"]
        geo.state = OK
        self.send("GEOGRAPHIC_COORD")
        utc = self.props["TIME_UTC"]
        utc["UTC"].value = st["mount_time_utc"].split(".")[0]
        utc.state = OK
        self.send("TIME_UTC")
        parked = op.get("kind") == "park" and op.get("phase") == "done"
        park = self.props["TELESCOPE_PARK"]
        if parked and "TELESCOPE_PARK" not in self.busy:
            park["PARK"].value, park["UNPARK"].value = True, False
            park.state = OK
            self.send("TELESCOPE_PARK")
        sat = self.props["SAT_PASS_WINDOW"]
        if op.get("kind") == "track_satellite":
            sat["SAT_PASS_WIN_START"].value = op["info"].get("pass_start_utc", "")
            sat["SAT_PASS_WIN_END"].value = op["info"].get("pass_end_utc", "")
            sat.state = OK
            self.send("SAT_PASS_WINDOW")


def _number(prop: str, name: str, text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"{prop}.{name}={text!r} is not a number") from None
    if not math.isfinite(value):
        raise ValueError(f"{prop}.{name}={text!r} is not a finite number")
    return value


async def run(url: str, password: str | None) -> None:
    loop = asyncio.get_running_loop()
    reader = asyncio.StreamReader()
    await loop.connect_read_pipe(lambda: asyncio.StreamReaderProtocol(reader), sys.stdin)

    def out(text: str) -> None:
        sys.stdout.write(text + "\n")
        sys.stdout.flush()

    scope = IndiTelescope(out, url, password)
    parser = Reader()

    async def poller() -> None:
        while True:
            await asyncio.sleep(POLL_S)
            try:
                await scope.poll()
            except (VssRequestError, ServerUnavailable, TimeoutError) as exc:
                log.warning("status poll: %s", exc)

    poll_task = loop.create_task(poller())
    try:
        while data := await reader.read(65536):
            for req in parser.feed(data):
                await scope.handle(req)
    finally:
        poll_task.cancel()
        if scope.vss is not None:
            await scope.vss.close()


def main() -> None:
    """Entry point of `vs-indi` (indiserver starts it; it speaks INDI on stdin/stdout)."""
    logging.basicConfig(level=logging.WARNING, stream=sys.stderr,
                        format="vs-indi %(levelname)s %(message)s")
    url = os.environ.get("VS_SERVER") or default_server_url()
    asyncio.run(run(url, os.environ.get(PASSWORD_ENV_VAR)))


if __name__ == "__main__":
    main()
