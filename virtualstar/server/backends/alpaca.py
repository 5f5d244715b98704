"""An ASCOM Alpaca telescope as a rate-driven mount: `alpaca://HOST:PORT/N`.

The Alpaca Device API is REST: GET members with ``ClientID``/``ClientTransactionID``
in the query, PUT methods with a form body, every answer a JSON object whose
``ErrorNumber`` is 0 or an ASCOM error (0x400 not implemented, 0x401 invalid value,
0x408 parked…). aiohttp (already the Alpaca façade's transport) keeps one
keep-alive connection, so a poll costs one request of about a millisecond.

What is read once, at connection: ``AlignmentMode`` (0 alt-az, 1 polar/fork, 2
German), ``CanMoveAxis`` and ``AxisRates`` of both axes (the largest rate is the
limit), ``CanPark``, ``CanPulseGuide``, the site. What is polled: ``DeviceState``
(ITelescopeV4: position, Slewing, Tracking, AtPark, SideOfPier in one request), or
the members one by one for an older driver.

The place is read from ``RightAscension`` and ``Declination`` themselves (a driver
answers them with where the mount is when asked; the ASCOM simulator's ``DeviceState``
carries the place of its last 100-ms update instead), the flags from ``DeviceState``.
Whether the answers are fresh at each request or sampled at the driver's own updates is
measured by the link (`rate_mount`), which stamps each report accordingly.

Rates: with tracking on, ``MoveAxis`` adds to the mount's sidereal tracking, so a
commanded *coordinate* rate is a MoveAxis rate on each axis. The sign of each axis
in the place of date differs between drivers (and with the pier side on a German
mount): it is measured at connection by `measure_signs` of the rate loop, not assumed.
"""

from __future__ import annotations

import asyncio
import itertools
from urllib.parse import urlsplit

from virtualstar.astro import Site

from ..exceptions import BadRequest, MountRejected
from .rate_mount import DriverInfo, DriverReport
from .rate_mount import _now_us as now_us  # the link's one wall clock for reports

__all__ = ["AlpacaDriver", "parse_alpaca_url"]

_GEOMETRY = {0: "altaz", 1: "fork", 2: "german"}  # ASCOM AlignmentModes: altaz, polar, GEM
CLIENT_ID = 7401  # any number: the driver groups a client's transactions by it


def parse_alpaca_url(url: str) -> tuple[str, int, int]:
    """Return (host, port, device number) of ``alpaca://HOST:PORT/N``; BadRequest if malformed."""
    parts = urlsplit(url)
    try:
        port = parts.port or 11111
        device = int(parts.path.strip("/") or 0)
    except ValueError:
        port, device = -1, -1
    if parts.scheme != "alpaca" or not parts.hostname or port <= 0 or device < 0:
        raise BadRequest(f"mount URL {url!r}: expected alpaca://HOST:PORT/DEVICE_NUMBER, "
                         "e.g. alpaca://127.0.0.1:11111/0")
    return parts.hostname, port, device


def geometry_override(url: str) -> str | None:
    """The ``geometry=`` of a mount URL's query (altaz, german, fork), or None; BadRequest."""
    from urllib.parse import parse_qs

    values = parse_qs(urlsplit(url).query).get("geometry")
    if not values:
        return None
    if values[-1] not in ("altaz", "german", "fork"):
        raise BadRequest(f"mount URL {url!r}: geometry={values[-1]!r}: expected altaz, german "
                         "or fork")
    return values[-1]


def _mark(k: int):
    """An aiohttp trace hook writing the time (µs) into slot `k` of the request's window."""
    async def hook(session, ctx, params) -> None:
        window = ctx.trace_request_ctx
        if isinstance(window, list):
            window[k] = now_us()

    return hook


def _span(*windows: list) -> tuple[int, int] | None:
    """The window holding both reads of a place (RA and Dec), or None if one was not seen."""
    if any(None in w for w in windows):
        return None
    return min(w[0] for w in windows), max(w[1] for w in windows)


class AlpacaDriver:
    """One ASCOM Alpaca telescope, polled over HTTP."""

    poll_s = 0.04  # the driver is read this often (with the request time: ~20 reports/s)
    # while latency matters (a goto, rates, a moving path: poll_pace.py), else 4 times a
    # second: at rest (parked, holding, tracking a star by itself) a report ≤ 0.25 s old
    # serves the status and the safety checks, at a fifth of the requests
    rest_poll_s = 0.25

    def __init__(self, url: str, *, timeout_s: float = 2.0) -> None:
        host, port, device = parse_alpaca_url(url)
        self.url = url
        # a driver that misstates its AlignmentMode: alpaca://...?geometry=german
        self.geometry = geometry_override(url)
        self.base = f"http://{host}:{port}/api/v1/telescope/{device}/"
        self.timeout_s = timeout_s
        self._session = None
        self._tx = itertools.count(1)
        self._device_state = True

    async def _request(self, method: str, member: str, window: list | None = None, **params):
        """One request; `window`, if given, gets [sent_us, answered_us]: when the request
        left (its headers written to the socket) and when the answer's headers came
        (aiohttp's request tracing). The driver computed its answer inside that window,
        which is shorter than the span around the whole call (connection pool, the event
        loop's turns before sending, the body's parsing)."""
        import aiohttp

        if self._session is None:
            trace = aiohttp.TraceConfig()
            trace.on_request_headers_sent.append(_mark(0))
            trace.on_request_end.append(_mark(1))
            self._session = aiohttp.ClientSession(
                timeout=aiohttp.ClientTimeout(total=self.timeout_s), trace_configs=[trace])
        ids = {"ClientID": CLIENT_ID, "ClientTransactionID": next(self._tx)}
        try:
            if method == "GET":
                resp = await self._session.get(self.base + member, params={**ids, **params},
                                               trace_request_ctx=window)
            else:
                resp = await self._session.put(self.base + member, data={**ids, **params})
            async with resp:
                if resp.status != 200:
                    text = (await resp.text())[:200]
                    raise MountRejected(f"Alpaca {method} {member}: HTTP {resp.status} {text}")
                doc = await resp.json(content_type=None)
        except aiohttp.ClientError as exc:
            raise OSError(f"Alpaca {method} {member}: {exc}") from None
        if not isinstance(doc, dict):
            raise MountRejected(f"Alpaca {member}: the answer is not a JSON object")
        number = doc.get("ErrorNumber", 0)
        if number:
            raise MountRejected(f"Alpaca {member}: error 0x{int(number):x}: "
                                f"{doc.get('ErrorMessage', '')}")
        return doc.get("Value")

    async def get(self, member: str, **params):
        return await self._request("GET", member, **params)

    async def _timed_get(self, member: str) -> tuple[object, list]:
        window = [None, None]
        value = await self._request("GET", member, window)
        return value, window

    async def put(self, member: str, **params):
        return await self._request("PUT", member, **params)

    async def open(self, site: Site) -> DriverInfo:
        await self.put("connected", Connected="true")
        mode = int(await self.get("alignmentmode"))
        name = str(await self.get("name"))
        rates = []
        for axis in (0, 1):
            if not await self.get("canmoveaxis", Axis=axis):
                raise MountRejected(f"{name}: axis {axis} cannot MoveAxis: the VSS needs rate "
                                    "axes to follow a target")
            ranges = await self.get("axisrates", Axis=axis) or []
            rates.append(max((float(r.get("Maximum", 0.0)) for r in ranges), default=0.0))
        can_park = bool(await self.get("canpark"))
        can_guide = bool(await self.get("canpulseguide"))
        try:
            driver_site = await self._site(site)
        except MountRejected:
            driver_site = None
        geometry = self.geometry or _GEOMETRY.get(mode, "german")
        return DriverInfo(name=name, geometry=geometry,
                          max_rate_deg_s=min(rates) or 1.0, rate_step_arcsec_s=None,
                          can_park=can_park, can_pulse_guide=can_guide, site=driver_site)

    async def _site(self, site: Site) -> tuple[float, float, float]:
        """The driver's site; the VSS's is sent first when it differs (the VSS's is the truth)."""
        here = (float(await self.get("sitelatitude")), float(await self.get("sitelongitude")),
                float(await self.get("siteelevation")))
        if abs(here[0] - site.lat_deg) > 1e-6 or abs((here[1] - site.lon_deg + 180) % 360 - 180) \
                > 1e-6:
            await self.put("sitelatitude", SiteLatitude=repr(site.lat_deg))
            await self.put("sitelongitude", SiteLongitude=repr(site.lon_deg))
            await self.put("siteelevation", SiteElevation=repr(site.height_m))
            here = (float(await self.get("sitelatitude")), float(await self.get("sitelongitude")),
                    float(await self.get("siteelevation")))
        return here

    async def close(self) -> None:
        if self._session is not None:
            await self._session.close()
            self._session = None

    async def read(self) -> DriverReport:
        if self._device_state:
            try:
                state, (ra, w_ra), (dec, w_dec) = await asyncio.gather(
                    self.get("devicestate"), self._timed_get("rightascension"),
                    self._timed_get("declination"))
                values = {d["Name"]: d["Value"] for d in state}
                return DriverReport(ra_h=float(ra), dec_deg=float(dec),
                                    slewing=bool(values["Slewing"]),
                                    tracking=bool(values["Tracking"]),
                                    at_park=bool(values["AtPark"]),
                                    side_of_pier=int(values.get("SideOfPier", -1)),
                                    window_us=_span(w_ra, w_dec))
            except (MountRejected, KeyError, TypeError):
                self._device_state = False  # an ITelescopeV3 driver: member by member
        (ra, w_ra), (dec, w_dec), slewing, tracking, park = await asyncio.gather(
            self._timed_get("rightascension"), self._timed_get("declination"),
            self.get("slewing"), self.get("tracking"), self.get("atpark"))
        return DriverReport(float(ra), float(dec), bool(slewing), bool(tracking), bool(park),
                            window_us=_span(w_ra, w_dec))

    async def goto_radec(self, ra_h: float, dec_deg: float) -> None:
        await self.put("slewtocoordinatesasync", RightAscension=f"{ra_h % 24.0:.9f}",
                       Declination=f"{dec_deg:.9f}")

    async def set_rates(self, ra_deg_s: float, dec_deg_s: float) -> None:
        await self.put("moveaxis", Axis=0, Rate=repr(float(ra_deg_s)))
        await self.put("moveaxis", Axis=1, Rate=repr(float(dec_deg_s)))

    async def set_tracking(self, on: bool) -> None:
        await self.put("tracking", Tracking="true" if on else "false")

    async def abort(self) -> None:
        await self.put("abortslew")

    async def park(self) -> None:
        await self.put("park")

    async def unpark(self) -> None:
        await self.put("unpark")

