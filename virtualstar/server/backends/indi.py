"""An INDI telescope as a rate-driven mount: `indi://HOST:PORT/DEVICE`.

INDI drivers run under indiserver and speak XML property vectors; indipyclient (a
maintained pure-Python INDI client, asyncio-based) keeps the connection and the
properties, and hands each update over as it arrives. The standard telescope
properties used (libindi's `INDI::Telescope`):

* ``EQUATORIAL_EOD_COORD`` (RA hours, DEC degrees of date): pushed by the driver
  at its polling period (the simulator's: 250 ms) whenever the place changes; its
  state is Busy during a goto. A report is stamped with its arrival.
* ``ON_COORD_SET`` TRACK + ``EQUATORIAL_EOD_COORD``: the goto; ``TELESCOPE_ABORT_MOTION``.
* ``TELESCOPE_TRACK_STATE``, ``TELESCOPE_TRACK_MODE`` (TRACK_CUSTOM) and
  ``TELESCOPE_TRACK_RATE`` (TRACK_RATE_RA, TRACK_RATE_DE, arcsec/s, the simulator's
  limit ±16 384″/s): the rate actuator. The RA member is the *axis* rate, sidereal
  included (15.04″/s holds a place of date); a commanded coordinate rate is taken
  off it. A finer actuator than the four steps of ``TELESCOPE_MOTION_NS/WE``.
* A driver pushes a place only when it changed: after `FRESH_READ_S` of silence the
  place is asked for again (``getProperties`` of the vector; the answer is a Define).
  An answer is a report of now; a driver that has answered nothing for `FRESH_FAIL_S`
  fails its reads (frozen), a shorter silence is a busy host.
* ``TELESCOPE_PARK``, ``TELESCOPE_PIER_SIDE`` (its presence: a German mount),
  ``GEOGRAPHIC_COORD`` (the VSS's site is sent when the driver's differs).
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import time
from urllib.parse import unquote, urlsplit

from virtualstar.astro import Site
from virtualstar.astro.constants import SIDEREAL_RATE_ARCSEC_S

from ..exceptions import BadRequest, MountRejected
from .alpaca import geometry_override
from .driver_waits import within
from .rate_mount import DriverInfo, DriverReport

__all__ = ["IndiDriver", "parse_indi_url"]

CONNECT_TIMEOUT_S = 10.0
PUSH_WAIT_S = 0.3  # a read waits this long for a new push; silence means "unchanged"
FRESH_READ_S = 1.0  # after this long without a push, the place is asked for again: a
# driver that answers is alive (a host that stalled is not a dead driver); one that does
# not answer grows old and ends the rate loop (a frozen driver)
FRESH_WAIT_S = 2.0  # how long a fresh read waits for the answer (a loaded host: seconds)
FRESH_FAIL_S = 10.0  # a driver that has answered nothing (push or fresh read) for this long
# fails its reads: a frozen driver. Shorter silences are a busy host (indiserver was seen
# to stall 3–5 s at load 15–25): the place counts as unchanged, as before


def parse_indi_url(url: str) -> tuple[str, int, str]:
    """Return (host, port, device) of ``indi://HOST:PORT/DEVICE``; BadRequest if malformed."""
    parts = urlsplit(url)
    try:
        port = parts.port or 7624
    except ValueError:
        port = -1
    device = unquote(parts.path.strip("/"))
    if parts.scheme != "indi" or not parts.hostname or port <= 0 or not device:
        raise BadRequest(f"mount URL {url!r}: expected indi://HOST:PORT/DEVICE, e.g. "
                         "indi://127.0.0.1:7624/Telescope%20Simulator")
    return parts.hostname, port, device


def _now_us() -> int:
    return time.time_ns() // 1000



class _Gone:
    state = "Gone"  # a vector of a lost connection: never Busy


_GONE = _Gone()

class IndiDriver:
    """One INDI telescope device, its properties pushed by indiserver."""

    poll_s = 0.0  # pushed: `read` waits for the next push

    def __init__(self, url: str, *, timeout_s: float = 2.0) -> None:
        self.host, self.port, self.device = parse_indi_url(url)
        self.url = url
        self.timeout_s = timeout_s
        self.geometry = geometry_override(url)
        self._client = None
        self._task: asyncio.Task | None = None
        self._pushed = asyncio.Event()
        self._place: tuple[float, float, int] | None = None  # ra_h, dec_deg, arrival µs
        self._read_place: tuple[float, float, int] | None = None
        self._written = (SIDEREAL_RATE_ARCSEC_S, 0.0)  # the TELESCOPE_TRACK_RATE last written
        self._answer = False  # the newest place answered a fresh read (not a tick's push)
        self.fresh_reads = 0  # fresh reads asked, and answered
        self.fresh_answers = 0
        self._defines = 0  # Defines of EQUATORIAL_EOD_COORD received (answers to getProperties)

    # ------------------------------------------------------------------ connection
    async def open(self, site: Site) -> DriverInfo:
        from indipyclient import IPyClient

        driver = self

        class Client(IPyClient):
            async def rxevent(self, event) -> None:
                if getattr(event, "devicename", None) != driver.device:
                    return
                if getattr(event, "vectorname", None) == "EQUATORIAL_EOD_COORD" and \
                        getattr(event, "eventtype", "") in ("Set", "Define"):
                    # a Define answers a fresh read (getProperties), a Set is a tick's push
                    answer = event.eventtype == "Define"
                    driver._defines += answer
                    driver._take_place(_now_us(), answer=answer)

        self._client = Client(indihost=self.host, indiport=self.port)
        self._client.debug_verbosity(0)
        self._task = asyncio.get_running_loop().create_task(self._client.asyncrun(),
                                                            name="indi-client")
        await self._wait(lambda: self._vector("CONNECTION") is not None, "the device")
        if self._vector("CONNECTION")["CONNECT"] != "On":
            await self._send("CONNECTION", {"CONNECT": "On", "DISCONNECT": "Off"})
        await self._wait(lambda: self._vector("EQUATORIAL_EOD_COORD") is not None
                         and self._vector("TELESCOPE_TRACK_RATE") is not None,
                         "its coordinates and track rate")
        # everything the device defined on connecting has arrived once it answers a request
        # sent after it (its output is one ordered stream): TELESCOPE_PIER_SIDE, which says a
        # German mount, may be defined after the coordinates and the track rate
        asked = self._defines
        await self._client.send_getProperties(self.device, "EQUATORIAL_EOD_COORD")
        await self._wait(lambda: self._defines > asked, "an answer to getProperties")
        if self._place is None:
            self._take_place(_now_us())
        rate = self._vector("TELESCOPE_TRACK_RATE")
        self._written = (rate.getfloatvalue("TRACK_RATE_RA"), rate.getfloatvalue("TRACK_RATE_DE"))
        await self._set_site(site)
        member = rate.member("TRACK_RATE_RA")
        max_rate = float(getattr(member, "max", 0.0) or 16384.0)
        step = float(getattr(member, "step", 0.0) or 0.0) or None
        geometry = self.geometry or ("german" if self._vector("TELESCOPE_PIER_SIDE") is not None
                                     else "fork")
        return DriverInfo(name=self.device, geometry=geometry,
                          max_rate_deg_s=(max_rate - SIDEREAL_RATE_ARCSEC_S) / 3600.0,
                          rate_step_arcsec_s=step,
                          can_park=self._vector("TELESCOPE_PARK") is not None,
                          can_pulse_guide=self._vector("TELESCOPE_TIMED_GUIDE_NS") is not None,
                          site=self._site(), slew_rate_deg_s=None)

    def _take_place(self, arrived_us: int, answer: bool = False) -> None:
        vector = self._vector("EQUATORIAL_EOD_COORD")
        self._place = (vector.getfloatvalue("RA"), vector.getfloatvalue("DEC"), arrived_us)
        self._answer = answer
        self._pushed.set()

    async def close(self) -> None:
        if self._client is not None:
            self._client.shutdown()
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await self._task
        self._client, self._task, self._place, self._read_place = None, None, None, None

    def _vector(self, name: str):
        """The device's vector `name`, or None (not defined, or the connection is gone)."""
        client = self._client
        if client is None or self.device not in client:
            return None
        return client[self.device].get(name)

    async def _wait(self, ready, what: str) -> None:
        deadline = time.monotonic() + CONNECT_TIMEOUT_S
        while not ready():
            if self._task is not None and self._task.done():
                raise OSError(f"INDI {self.host}:{self.port}: the connection ended")
            if time.monotonic() > deadline:
                raise OSError(f"INDI {self.host}:{self.port}: device {self.device!r} did not "
                              f"define {what} within {CONNECT_TIMEOUT_S:g} s")
            await asyncio.sleep(0.05)

    def _alive(self) -> None:
        client = self._client
        if client is None or not client.connected:
            raise OSError(f"INDI {self.host}:{self.port}: not connected")

    async def _send(self, vector: str, members: dict) -> None:
        self._alive()
        if self._vector(vector) is None:
            raise MountRejected(f"INDI {self.device}: no property {vector}")
        await self._client.send_newVector(self.device, vector, members=members)

    def _site(self) -> tuple[float, float, float] | None:
        geo = self._vector("GEOGRAPHIC_COORD")
        if geo is None:
            return None
        lon = geo.getfloatvalue("LONG")
        return geo.getfloatvalue("LAT"), (lon + 180.0) % 360.0 - 180.0, geo.getfloatvalue("ELEV")

    async def _set_site(self, site: Site) -> None:
        here = self._site()
        if here is None:
            return
        if abs(here[0] - site.lat_deg) < 1e-6 and abs((here[1] - site.lon_deg + 180) % 360 - 180) \
                < 1e-6:
            return
        await self._send("GEOGRAPHIC_COORD", {"LAT": site.lat_deg,
                                              "LONG": site.lon_deg % 360.0,
                                              "ELEV": site.height_m})
        await self._wait(lambda: self._site() is not None and abs(self._site()[0] - site.lat_deg)
                         < 1e-6, "the site the VSS sent")

    # ------------------------------------------------------------------ reports
    async def read(self) -> DriverReport:
        self._alive()
        with contextlib.suppress(TimeoutError):
            await within(self._pushed.wait(), PUSH_WAIT_S)  # never drops a cancel
        if not self._pushed.is_set() and self._place is not None \
                and _now_us() - self._place[2] > FRESH_READ_S * 1e6:
            await self._fresh_read()
        self._pushed.clear()
        self._alive()
        place = self._place
        if place is None:
            raise OSError(f"INDI {self.device}: no coordinates yet")
        fresh = place is not self._read_place
        self._read_place = place
        eq = self._vector("EQUATORIAL_EOD_COORD")
        if eq is None:
            raise OSError(f"INDI {self.device}: EQUATORIAL_EOD_COORD is gone (connection lost)")
        track = self._vector("TELESCOPE_TRACK_STATE")
        park = self._vector("TELESCOPE_PARK")
        pier = self._vector("TELESCOPE_PIER_SIDE")
        side = -1
        if pier is not None:
            side = 0 if pier["PIER_EAST"] == "On" else 1 if pier["PIER_WEST"] == "On" else -1
        return DriverReport(ra_h=place[0], dec_deg=place[1],
                            slewing=eq.state == "Busy",
                            tracking=track is not None and track["TRACK_ON"] == "On",
                            at_park=park is not None and park["PARK"] == "On",
                            side_of_pier=side,
                            # a push describes the moment it arrived; silence: unchanged now
                            received_us=place[2] if fresh else None,
                            answered=fresh and self._answer)

    async def _fresh_read(self) -> None:
        """Ask the driver for its place again (it pushes only a place that changed); an
        answer (a Define of the vector) is a report of now. No answer: the place ages."""
        self._pushed.clear()
        await self._client.send_getProperties(self.device, "EQUATORIAL_EOD_COORD")
        self.fresh_reads += 1
        with contextlib.suppress(TimeoutError):
            await within(self._pushed.wait(), FRESH_WAIT_S)
        if not self._pushed.is_set():
            silent_s = (_now_us() - self._place[2]) / 1e6 if self._place else math.inf
            if silent_s > FRESH_FAIL_S:
                # a failed read: the link calls the driver lost after a few over `stale_s`
                raise OSError(f"INDI {self.device}: no answer to a fresh read of "
                              f"EQUATORIAL_EOD_COORD, nothing from the driver for "
                              f"{silent_s:.0f} s")
            return
        self.fresh_answers += 1

    # ------------------------------------------------------------------ commands
    async def goto_radec(self, ra_h: float, dec_deg: float) -> None:
        await self._send("ON_COORD_SET", {"TRACK": "On", "SLEW": "Off", "SYNC": "Off"})
        await self._send("EQUATORIAL_EOD_COORD", {"RA": ra_h % 24.0, "DEC": dec_deg})
        # the driver flags the goto (Busy) when it has taken it
        await self._wait(lambda: (self._vector("EQUATORIAL_EOD_COORD") or _GONE).state == "Busy"
                         or self._is_close(ra_h, dec_deg), "the goto")

    def _is_close(self, ra_h: float, dec_deg: float) -> bool:
        p = self._place
        return p is not None and abs((p[0] - ra_h + 12) % 24 - 12) < 1e-4 and abs(p[1] - dec_deg) < 1e-3

    async def set_rates(self, ra_deg_s: float, dec_deg_s: float) -> None:
        mode = self._vector("TELESCOPE_TRACK_MODE")
        if mode is None:  # the connection was lost (indiserver may drop a slow client)
            raise OSError(f"INDI {self.device}: TELESCOPE_TRACK_MODE is gone (connection lost)")
        if not (ra_deg_s or dec_deg_s):
            # no offset: the mount's own sidereal tracking (libindi refuses a custom rate that
            # equals sidereal, and keeps the last one: the mount would go on turning)
            if mode["TRACK_SIDEREAL"] != "On":
                await self._send("TELESCOPE_TRACK_MODE", {
                    m: ("On" if m == "TRACK_SIDEREAL" else "Off") for m in mode.members()})
            return
        # the axis turns at sidereal minus the place's own rate (arcsec/s)
        want = (SIDEREAL_RATE_ARCSEC_S - ra_deg_s * 3600.0, dec_deg_s * 3600.0)
        if mode["TRACK_CUSTOM"] == "On" and (want[0] * self._written[0] < 0
                                             or want[1] * self._written[1] < 0):
            # libindi refuses, while tracking at custom rates, a rate whose sign differs from
            # the one last *written* (refused ones included: it stores them first) and says
            # so only in a message: an axis that must turn the other way goes through zero
            await self._write_rates(tuple(w if w * o >= 0 else 0.0
                                          for w, o in zip(want, self._written, strict=True)))
        await self._write_rates(want)
        if mode["TRACK_CUSTOM"] != "On":
            # the driver's own mode, not a remembered one (a goto or abort may reset it)
            await self._send("TELESCOPE_TRACK_MODE",
                             {m: ("On" if m == "TRACK_CUSTOM" else "Off") for m in mode.members()})

    async def _write_rates(self, rates: tuple[float, ...]) -> None:
        await self._send("TELESCOPE_TRACK_RATE", {"TRACK_RATE_RA": rates[0],
                                                  "TRACK_RATE_DE": rates[1]})
        self._written = (float(rates[0]), float(rates[1]))

    async def set_tracking(self, on: bool) -> None:
        await self._send("TELESCOPE_TRACK_STATE", {"TRACK_ON": "On" if on else "Off",
                                                   "TRACK_OFF": "Off" if on else "On"})

    async def abort(self) -> None:
        await self._send("TELESCOPE_ABORT_MOTION", {"ABORT": "On"})

    async def park(self) -> None:
        await self._send("TELESCOPE_PARK", {"PARK": "On", "UNPARK": "Off"})

    async def unpark(self) -> None:
        await self._send("TELESCOPE_PARK", {"PARK": "Off", "UNPARK": "On"})

