"""`vs-indi`: an INDI telescope driver, run by indiserver, that drives the VirtualStar Server.

    indiserver vs-indi            # the VSS from $VS_SERVER (default ws://127.0.0.1:8740),
                                  # its operator password from $VS_PASSWORD

Standard telescope properties map onto VSS commands (docs/alpaca-indi.md):
EQUATORIAL_EOD_COORD (JNow) with ON_COORD_SET TRACK/SLEW → `slew` (SLEW then `stop`s
tracking), TELESCOPE_ABORT_MOTION → `stop`, TELESCOPE_PARK → `park`,
TELESCOPE_TRACK_STATE → `track` of where it points / `stop`, TELESCOPE_MOTION_NS/WE →
`move`, TELESCOPE_TIMED_GUIDE_NS/WE → `guide`, HORIZONTAL_COORD → `slew` to az/el,
SAT_TLE_TEXT + SAT_TRACKING_STAT → `track` of the TLE, VS_OFFSET / VS_OFFSET_RESET →
`offset`, VS_CLOSED_LOOP → tracks guided by the guide camera (offsets.py). States stay true to the
operation: a coordinate property is Busy from the command until the VSS says the
mount arrived (Ok) or failed (Alert); the periodic status poll updates values but
never overwrites Busy.
"""

from __future__ import annotations

import asyncio
import contextvars
import logging
import math
import os
import sys
import xml.etree.ElementTree as ET
from typing import Any

from virtualstar.astro.constants import SIDEREAL_RATE_ARCSEC_S
from virtualstar.astro.equatorial import icrs_to_jnow, jnow_to_icrs
from virtualstar.vss_client import (
    PASSWORD_ENV_VAR,
    ServerUnavailable,
    VssClient,
    VssRequestError,
    default_server_url,
)
from virtualstar.vss_operations import hand_pad_rates, is_moving, is_parked, is_tracking

from .offsets import offset_requests, offset_vectors, offsets_from_status
from .protocol import ALERT, BUSY, IDLE, OK, Element, Reader, Request, Vector

__all__ = ["IndiTelescope", "main"]

log = logging.getLogger("virtualstar.indi")

#: How many TELESCOPE_ABORT_MOTIONs had arrived when the request being served arrived
#: (None: not a client's request, e.g. the status poll). Tasks a handler spawns inherit it.
_ABORTS_BEFORE: contextvars.ContextVar[int | None] = contextvars.ContextVar(
    "aborts_before", default=None)


class AbortedBeforeSent(ValueError):
    """A request that would move the mount arrived before an abort still being served."""

DEVICE = "VirtualStar"
POLL_S = 1.0
MOTION_RATE_DEG_S = 1.0  # TELESCOPE_MOTION_* hand-pad rate
GUIDE_RATE_ARCSEC_S = 0.5 * SIDEREAL_RATE_ARCSEC_S  # ASCOM's and INDI's usual default
MOTION_KINDS = frozenset({"slew", "track", "park", "move", "pointing_sample"})
#: The VSS commands that set the mount moving: none is sent for a request that arrived
#: before a TELESCOPE_ABORT_MOTION (an abort is final for everything sent before it).
MOVING_COMMANDS = frozenset({"slew", "track", "park", "move", "guide", "offset"})
SITE_TOLERANCE_DEG = 0.01  # a client's location within this of the VSS's site is the same
TIME_TOLERANCE_S = 60.0  # a client's UTC within this of the mount clock is the same
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
               [_s("TRACK", "Track", True), _s("SLEW", "Slew")]),  # no SYNC: models, not syncs
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
                _n("ELEV", "Elevation (m)", "%g", -200, 10000)]),
        Vector(d, "TIME_UTC", "Text", "UTC", SITE,
               [Element("UTC", "UTC Time", ""), Element("OFFSET", "UTC Offset", "0")]),
        Vector(d, "TELESCOPE_INFO", "Number", "Scope Properties", "Options",
               [_n("TELESCOPE_APERTURE", "Aperture (mm)", "%g", 10, 5000),
                _n("TELESCOPE_FOCAL_LENGTH", "Focal Length (mm)", "%g", 10, 50000),
                _n("GUIDER_APERTURE", "Guider Aperture (mm)", "%g", 10, 5000),
                _n("GUIDER_FOCAL_LENGTH", "Guider Focal Length (mm)", "%g", 10, 50000)]),
        Vector(d, "SAT_TLE_TEXT", "Text", "Orbit Params", SAT, [Element("TLE", "TLE", "")]),
        Vector(d, "SAT_PASS_WINDOW", "Text", "Pass Window", SAT,
               [Element("SAT_PASS_WINDOW_START", "Start", ""),
                Element("SAT_PASS_WINDOW_END", "End", "")]),
        Vector(d, "SAT_TRACKING_STAT", "Switch", "Sat tracking", SAT,
               [_s("SAT_TRACK", "Track"), _s("SAT_HALT", "Halt", True)]),
        *offset_vectors(d),
    ]


class IndiTelescope:
    """The driver's state and handlers; `out(text)` writes XML to indiserver.

    What the telescope does is read from the VSS status; the driver remembers only which
    of its own commands a property waits for (`busy`: property → generation, so a
    superseded command's answer is dropped), the park it released, and the client's
    pass window.
    """

    def __init__(self, out, url: str, password: str | None) -> None:
        self.out = out
        self.url = url
        self.password = password
        self.props = {v.name: v for v in properties()}
        self.vss: VssClient | None = None
        self.busy: dict[str, int] = {}
        self.generation = 0
        self.pulse_end_us: dict[str, tuple[int, int]] = {}  # guide property → (op id, end µs)
        self.unparked_op: int | None = None
        self.window_from_client = False
        self.last_op_id: int | None = None  # the VSS operation the last poll saw
        self.alert_op: dict[str, int | None] = {}  # property → operation its Alert was about
        self.tasks: set[asyncio.Task] = set()
        # aborts counted as they arrive (before they are served), so that a goto queued or
        # half-handled ahead of an abort can never reach the VSS after the abort's stop
        self.aborts_received = 0

    # ------------------------------------------------------------------ output
    def send(self, name: str, message: str | None = None) -> None:
        self.out(self.props[name].set_xml(message))

    def set_state(self, name: str, state: str, message: str | None = None) -> None:
        self.props[name].state = state
        self.busy.pop(name, None)
        if state == ALERT:  # it stays Alert until the telescope does something else
            self.alert_op[name] = self.last_op_id
        self.send(name, message)

    def spawn(self, coro) -> None:
        task = asyncio.get_running_loop().create_task(coro)
        self.tasks.add(task)
        task.add_done_callback(self._done)

    def _done(self, task: asyncio.Task) -> None:
        self.tasks.discard(task)
        if not task.cancelled() and task.exception() is not None:
            log.error("internal error: %r", task.exception())

    # ------------------------------------------------------------------ input
    def received(self, req: Request) -> int:
        """Count `req` in as it arrives; return the aborts received before it (or with it,
        for an abort). Call in arrival order, before any request is served."""
        if req.device in (None, DEVICE) and req.name == "TELESCOPE_ABORT_MOTION" \
                and req.tag != "getProperties":
            self.aborts_received += 1
        return self.aborts_received

    async def handle(self, req: Request, aborts_before: int | None = None) -> None:
        """Answer one request; whatever goes wrong, the property says so (Alert).

        `aborts_before` (from `received`): the request does not move the mount if an abort
        arrived after it."""
        _ABORTS_BEFORE.set(aborts_before)
        if req.tag == "getProperties":
            if req.device in (None, DEVICE):
                for v in self.props.values():
                    if req.name in (None, v.name):
                        self.out(v.define_xml())
            return
        if req.device != DEVICE or req.name not in self.props:
            return
        prop = self.props[req.name]
        try:
            if prop.perm == "ro":
                raise ValueError(f"{prop.name} is read-only")
            if req.name != "CONNECTION" and self.vss is None:
                raise ValueError("not connected: switch CONNECTION to CONNECT")
            handler = getattr(self, f"on_{prop.name.lower()}", None)
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
        except Exception as exc:  # a bug must not end the driver: say it, keep serving
            log.exception("%s: internal error", prop.name)
            self.set_state(prop.name, ALERT, f"internal error: {exc!r}")

    @staticmethod
    def _store(prop: Vector, members: dict[str, str]) -> None:
        """Apply a client's values (all or nothing); switch rules as libindi enforces them."""
        unknown = sorted(set(members) - set(prop.index))
        if unknown:
            raise ValueError(f"{prop.name} has no member {', '.join(unknown)}; it has "
                             f"{', '.join(prop.index)}")
        new: dict[str, Any] = {}
        for name, text in members.items():
            if prop.kind == "Number":
                new[name] = _number(prop.name, name, text)
            elif prop.kind == "Switch":
                if text.strip() not in ("On", "Off"):
                    raise ValueError(f"{prop.name}.{name}={text!r}: expected On or Off")
                new[name] = text.strip() == "On"
            else:
                new[name] = text
        if prop.kind == "Switch":
            after = {e.name: e.value for e in prop.elements}
            on = [n for n, v in new.items() if v]
            if prop.rule == "OneOfMany" and on:  # one On: the others go Off
                after = {n: n == on[-1] for n in after}
            else:
                after.update(new)
            count = sum(bool(v) for v in after.values())
            if prop.rule == "OneOfMany" and count != 1:
                raise ValueError(f"{prop.name}: exactly one of {', '.join(after)} must be On")
            if prop.rule == "AtMostOne" and count > 1:
                raise ValueError(f"{prop.name}: at most one of {', '.join(after)} may be On")
            new = after
        for name, value in new.items():
            prop[name].value = value

    async def request(self, cmd: str, params: dict[str, Any] | None = None,
                      timeout_s: float | None = 30.0) -> Any:
        assert self.vss is not None
        self.refuse_if_aborted(cmd)
        return await self.vss.request(cmd, params or {}, timeout_s)

    def refuse_if_aborted(self, cmd: str) -> None:
        """Raise AbortedBeforeSent if `cmd` moves the mount and an abort arrived after the
        request being served (checked again just before sending: handlers await)."""
        before = _ABORTS_BEFORE.get()
        if cmd in MOVING_COMMANDS and before is not None and before < self.aborts_received:
            raise AbortedBeforeSent(f"aborted: TELESCOPE_ABORT_MOTION arrived after this "
                                    f"request, so its {cmd} was not sent")

    async def mount_status(self) -> dict[str, Any]:
        st = await self.request("status")
        if "mount_time_us" not in st:
            raise ValueError("the VirtualStar Server has no mount connected "
                             f"({st.get('mount_error') or 'connecting'})")
        return st

    async def refuse_if_parked(self, what: str) -> dict[str, Any]:
        st = await self.mount_status()
        if self.parked(st):
            raise ValueError(f"{what}: the mount is parked; UNPARK first")
        return st

    def parked(self, st: dict[str, Any]) -> bool:
        return is_parked(st.get("operation"), self.unparked_op)

    def begin(self, prop_name: str, cmd: str, params: dict[str, Any], then=None) -> None:
        """Send an operation; the property is Busy until it lands (Ok) or fails (Alert).

        A newer command on the same property supersedes this one: its answer is dropped.
        """
        self.refuse_if_aborted(cmd)
        self.generation += 1
        mine = self.generation
        self.set_state(prop_name, BUSY)
        self.busy[prop_name] = mine

        async def run() -> None:
            try:
                await self.request(cmd, params, None)
            except (VssRequestError, ServerUnavailable, AbortedBeforeSent) as exc:
                if self.busy.get(prop_name) == mine:
                    code = f" [VSS {exc.code}]" if isinstance(exc, VssRequestError) else ""
                    self.set_state(prop_name, ALERT, f"{getattr(exc, 'message', exc)}{code}")
                return
            if self.busy.get(prop_name) == mine:
                self.set_state(prop_name, OK)
                if then is not None:
                    await then()

        self.spawn(run())

    # ------------------------------------------------------------------ handlers
    async def on_connection(self, prop: Vector, members: dict[str, str]) -> None:
        self._store(prop, members)
        if prop["CONNECT"].value:
            if self.vss is None:
                try:
                    client = await VssClient.connect(self.url, reconnect=True,
                                                     password=self.password)
                except (ServerUnavailable, VssRequestError):
                    prop["CONNECT"].value, prop["DISCONNECT"].value = False, True
                    raise
                if client.role != "operator":
                    await client.close()
                    prop["CONNECT"].value, prop["DISCONNECT"].value = False, True
                    raise ValueError(f"{self.url} gave the observer role: set $VS_PASSWORD to "
                                     "the operator password")
                self.vss = client
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
        st = await self.refuse_if_parked("goto")
        ra, dec_icrs = jnow_to_icrs(ra_h * 15.0, dec, st["mount_time_us"])
        slew_only = self.props["ON_COORD_SET"]["SLEW"].value

        async def stop_tracking() -> None:  # SLEW: go there and stay (INDI's meaning)
            await self.request("stop")

        self.begin(prop.name, "slew", {"ra_deg": ra, "dec_deg": dec_icrs},
                   then=stop_tracking if slew_only else None)

    async def on_horizontal_coord(self, prop: Vector, members: dict[str, str]) -> None:
        az = _number(prop.name, "AZ", members.get("AZ", ""))
        alt = _number(prop.name, "ALT", members.get("ALT", ""))
        if not (0 <= az < 360 and -90 <= alt <= 90):
            raise ValueError(f"AZ {az:g}, ALT {alt:g}: expected 0 <= AZ < 360, -90..90")
        await self.refuse_if_parked("goto")
        self.begin(prop.name, "slew", {"az_deg": az, "el_deg": alt})

    async def on_telescope_abort_motion(self, prop: Vector, members: dict[str, str]) -> None:
        busy = list(self.busy)
        await self.request("stop")
        for name in busy:
            self.set_state(name, ALERT, "aborted")
        for name in ("TELESCOPE_MOTION_NS", "TELESCOPE_MOTION_WE"):
            for e in self.props[name].elements:
                e.value = False
            self.set_state(name, IDLE)
        prop["ABORT"].value = False
        self.set_state(prop.name, OK, "motion aborted")

    async def on_telescope_park(self, prop: Vector, members: dict[str, str]) -> None:
        self._store(prop, members)
        if prop["PARK"].value:
            self.unparked_op = None
            self.begin(prop.name, "park", {"wait": True})
            return
        op = (await self.mount_status()).get("operation") or {}
        if op.get("kind") == "park":
            self.unparked_op = op.get("id")
        self.set_state(prop.name, OK, "unparked")

    async def on_telescope_track_state(self, prop: Vector, members: dict[str, str]) -> None:
        self._store(prop, members)
        if prop["TRACK_ON"].value:
            st = await self.refuse_if_parked("tracking")
            self.begin(prop.name, "track", dict(st["radec"]))
        else:
            await self.request("stop")
            self.set_state(prop.name, IDLE)

    async def _motion(self, prop: Vector, members: dict[str, str]) -> None:
        self._store(prop, members)
        ns, we = self.props["TELESCOPE_MOTION_NS"], self.props["TELESCOPE_MOTION_WE"]
        el_rate = MOTION_RATE_DEG_S * (ns["MOTION_NORTH"].value - ns["MOTION_SOUTH"].value)
        az_rate = MOTION_RATE_DEG_S * (we["MOTION_EAST"].value - we["MOTION_WEST"].value)
        if az_rate == 0 and el_rate == 0:
            await self.request("stop")
            for name in ("TELESCOPE_MOTION_NS", "TELESCOPE_MOTION_WE"):
                self.set_state(name, IDLE)
            return
        await self.refuse_if_parked("motion")
        await self.request("move", {"az_rate_deg_s": az_rate, "el_rate_deg_s": el_rate}, None)
        self.set_state(prop.name, BUSY)

    on_telescope_motion_ns = _motion
    on_telescope_motion_we = _motion

    async def _guide(self, prop: Vector, members: dict[str, str]) -> None:
        self._store(prop, members)
        values = {n: float(v) for n, v in prop.values().items()}
        for e in prop.elements:
            e.value = 0.0
        north = values.get("TIMED_GUIDE_N", 0.0) - values.get("TIMED_GUIDE_S", 0.0)
        east = values.get("TIMED_GUIDE_E", 0.0) - values.get("TIMED_GUIDE_W", 0.0)
        ms = north if prop.name.endswith("NS") else east
        if ms == 0:
            self.set_state(prop.name, OK)
            return
        size = GUIDE_RATE_ARCSEC_S * abs(ms) / 1000.0 * math.copysign(1.0, ms)
        key = "north_arcsec" if prop.name.endswith("NS") else "east_arcsec"
        pulse = await self.request("guide", {key: size, "rate_arcsec_s": GUIDE_RATE_ARCSEC_S})
        self.set_state(prop.name, BUSY)
        self.pulse_end_us[prop.name] = (int(pulse["id"]), int(pulse["end_us"]))

    on_telescope_timed_guide_ns = _guide
    on_telescope_timed_guide_we = _guide

    async def on_sat_pass_window(self, prop: Vector, members: dict[str, str]) -> None:
        self._store(prop, members)
        start, end = (str(prop[k].value).strip() for k in ("SAT_PASS_WINDOW_START",
                                                            "SAT_PASS_WINDOW_END"))
        if not start and not end:
            self.window_from_client = False
            self.set_state(prop.name, IDLE)
            return
        begin_us, end_us = _window_us(start, end)
        if end_us <= begin_us:
            raise ValueError(f"SAT_PASS_WINDOW: the end {end} is not after the start {start}")
        self.window_from_client = True
        self.set_state(prop.name, OK)

    async def on_sat_tracking_stat(self, prop: Vector, members: dict[str, str]) -> None:
        self._store(prop, members)
        if not prop["SAT_TRACK"].value:
            await self.request("stop")
            self.set_state(prop.name, IDLE)
            return
        tle = str(self.props["SAT_TLE_TEXT"]["TLE"].value)
        if not tle.strip():
            raise ValueError("set SAT_TLE_TEXT (the TLE: name line and two element lines) first")
        st = await self.refuse_if_parked("satellite tracking")
        params: dict[str, Any] = {"tle": tle, "wait": True, **self.closed_loop()}
        if self.window_from_client:
            w = self.props["SAT_PASS_WINDOW"]
            _start_us, end_us = _window_us(str(w["SAT_PASS_WINDOW_START"].value),
                                           str(w["SAT_PASS_WINDOW_END"].value))
            if end_us <= st["mount_time_us"]:
                raise ValueError("SAT_PASS_WINDOW ended before the mount time "
                                 f"{st['mount_time_utc']}")
            # only a pass that begins before the window's end
            params["max_wait_s"] = (end_us - st["mount_time_us"]) / 1e6
        self.begin(prop.name, "track", params)

    def closed_loop(self) -> dict[str, Any]:
        """{"closed_loop": True} while VS_CLOSED_LOOP is On, else {}."""
        return {"closed_loop": True} if self.props["VS_CLOSED_LOOP"]["CLOSED_LOOP_ON"].value \
            else {}

    async def on_vs_offset(self, prop: Vector, members: dict[str, str]) -> None:
        before = prop.values()
        self._store(prop, members)  # checks names, numbers and ranges first, all or nothing
        given = {n: float(prop[n].value) for n in members}
        for n, v in before.items():
            prop[n].value = v  # the values shown follow the server's status, not the request
        for params in offset_requests(given):
            await self.request("offset", params)
        self.set_state(prop.name, OK)

    async def on_vs_offset_reset(self, prop: Vector, members: dict[str, str]) -> None:
        self._store(prop, members)
        if prop["RESET"].value:
            prop["RESET"].value = False
            await self.request("offset", {"axis": "all", "op": "reset"})
        self.set_state(prop.name, OK)

    async def on_geographic_coord(self, prop: Vector, members: dict[str, str]) -> None:
        site = (await self.request("status"))["site"]
        given = {n: _number(prop.name, n, t) for n, t in members.items()}
        theirs = {"LAT": site["lat_deg"], "LONG": site["lon_deg"] % 360.0}
        off = [f"{n} {given[n]:g} (the server's {theirs[n]:g})" for n in theirs
               if n in given and abs((given[n] - theirs[n] + 180) % 360 - 180) > SITE_TOLERANCE_DEG]
        if off:
            raise ValueError("the site is the VirtualStar Server's (its --site-file): "
                             + ", ".join(off))
        self.set_state(prop.name, OK, "the client's location is the server's site")

    async def on_time_utc(self, prop: Vector, members: dict[str, str]) -> None:
        st = await self.mount_status()
        text = members.get("UTC", "").strip()
        (t_us, _end) = _window_us(text, text)
        off_s = (t_us - st["mount_time_us"]) / 1e6
        if abs(off_s) > TIME_TOLERANCE_S:
            raise ValueError(f"UTC {text} is {off_s:+.0f} s from the mount clock "
                             f"{st['mount_time_utc']}; the mount's clock is disciplined by its "
                             "PPS and the VSS's time sync, not set by clients")
        self.set_state(prop.name, OK, "the client's time agrees with the mount clock")

    # ------------------------------------------------------------------ status poll
    async def poll(self) -> None:
        """Refresh values from the VSS; a property Busy with a command of ours stays Busy."""
        if self.vss is None:
            return
        st = await self.request("status")
        if "mount_time_us" not in st:
            return
        t_us = st["mount_time_us"]
        current = st.get("operation")
        op = current or {}
        kind = op.get("kind")
        self.last_op_id = op.get("id")
        for name, about in list(self.alert_op.items()):
            if about != self.last_op_id:
                del self.alert_op[name]
                if self.props[name].state == ALERT and name not in self.busy:
                    self.props[name].state = IDLE
        moving = kind in MOTION_KINDS and is_moving(current)
        tracking = is_tracking(current)
        ra, dec = icrs_to_jnow(st["radec"]["ra_deg"], st["radec"]["dec_deg"], t_us)
        eq = self.props["EQUATORIAL_EOD_COORD"]
        eq["RA"].value, eq["DEC"].value = ra / 15.0, dec
        hz = self.props["HORIZONTAL_COORD"]
        hz["AZ"].value, hz["ALT"].value = st["observed"]["az_deg"] % 360.0, st["observed"]["el_deg"]
        for name in ("EQUATORIAL_EOD_COORD", "HORIZONTAL_COORD"):
            if name not in self.busy and self.props[name].state != ALERT:
                # a motion another client (or the server) started shows as Busy too
                self.props[name].state = BUSY if moving else OK
            self.send(name)
        if hand_pad_rates(current) == [0.0, 0.0]:  # the hand pad's move ended
            for name in ("TELESCOPE_MOTION_NS", "TELESCOPE_MOTION_WE"):
                motion = self.props[name]
                if motion.state == BUSY:
                    for e in motion.elements:
                        e.value = False
                    self.set_state(name, IDLE)
        ts = self.props["TELESCOPE_TRACK_STATE"]
        ts["TRACK_ON"].value, ts["TRACK_OFF"].value = tracking, not tracking
        if "TELESCOPE_TRACK_STATE" not in self.busy:
            ts.state = BUSY if tracking else IDLE
        self.send("TELESCOPE_TRACK_STATE")
        for name, (op_id, end) in list(self.pulse_end_us.items()):
            if t_us >= end or op.get("id") != op_id:
                del self.pulse_end_us[name]
                if self.props[name].state == BUSY:
                    self.set_state(name, OK if op.get("id") == op_id else ALERT)
        site = st["site"]
        geo = self.props["GEOGRAPHIC_COORD"]
        geo["LAT"].value, geo["LONG"].value = site["lat_deg"], site["lon_deg"] % 360.0
        geo["ELEV"].value = site["height_m"]
        self.send("GEOGRAPHIC_COORD")
        utc = self.props["TIME_UTC"]
        utc["UTC"].value = st["mount_time_utc"].split(".")[0]
        self.send("TIME_UTC")
        park = self.props["TELESCOPE_PARK"]
        if "TELESCOPE_PARK" not in self.busy:
            parked = self.parked(st)
            if park["PARK"].value != parked:
                park["PARK"].value, park["UNPARK"].value = parked, not parked
                park.state = OK
                self.send("TELESCOPE_PARK")
        offsets = self.props["VS_OFFSET"]
        for member, value in offsets_from_status(st).items():
            offsets[member].value = value
        self.send("VS_OFFSET")
        window = self.props["SAT_PASS_WINDOW"]
        if kind == "track_satellite" and not self.window_from_client:
            window["SAT_PASS_WINDOW_START"].value = op["info"].get("pass_start_utc", "")
            window["SAT_PASS_WINDOW_END"].value = op["info"].get("pass_end_utc", "")
            window.state = OK
            self.send("SAT_PASS_WINDOW")


def _window_us(start: str, end: str) -> tuple[int, int]:
    """Mount times (µs) of two ISO-8601 UTC texts; ValueError naming what is wrong."""
    from virtualstar.astro import UtcTimes
    from virtualstar.astro.exceptions import AstroError

    out = []
    for text in (start, end):
        try:
            out.append(int(UtcTimes.from_iso([text if text.endswith("Z") else text + "Z"])
                           .to_unix_us()[0]))
        except (AstroError, ValueError):
            raise ValueError(f"{text!r}: expected an ISO-8601 UTC time, e.g. "
                             "2024-05-18T21:10:00") from None
    return out[0], out[1]


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
    queue: asyncio.Queue[tuple[Request, int]] = asyncio.Queue()

    async def worker() -> None:  # requests in the order they came ...
        while True:
            await scope.handle(*await queue.get())

    async def poller() -> None:
        while True:
            await asyncio.sleep(POLL_S)
            try:
                await scope.poll()
            except (VssRequestError, ServerUnavailable, TimeoutError, KeyError) as exc:
                log.warning("status poll: %s", exc)

    tasks = [loop.create_task(poller()), loop.create_task(worker())]
    try:
        while data := await reader.read(65536):
            try:
                requests = list(parser.feed(data))
            except ET.ParseError as exc:
                log.error("unreadable XML from indiserver (%s): the stream starts afresh", exc)
                parser = Reader()
                continue
            for req in requests:
                aborts = scope.received(req)
                if req.name == "TELESCOPE_ABORT_MOTION":
                    # ... but an abort never waits its turn (and what came before it
                    # will not move the mount: `received` counted it first)
                    scope.spawn(scope.handle(req, aborts))
                else:
                    queue.put_nowait((req, aborts))
    finally:
        for task in tasks:
            task.cancel()
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
