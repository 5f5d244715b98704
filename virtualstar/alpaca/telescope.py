"""ITelescopeV4 on the VSS: every member, answered from the VSS status or sent as a VSS command.

The façade owns no motion: slews are VSS `slew`, tracking a VSS `track` of the place
the telescope points at, MoveAxis a VSS `move`, PulseGuide a VSS `guide`, park a VSS
`park`, AbortSlew a VSS `stop`, satellites the `TrackSatellite` action (a VSS `track`
of a TLE). The VSS answers a slew only once it has landed, so an *Async member returns
as soon as the VSS has accepted the operation (its checks passed: Sun zone, horizon,
limits), and the client polls Slewing. A refusal comes back as an ASCOM error with the
VSS's message.

Coordinates: RightAscension/Declination are FK5 J2000 (EquatorialSystem 2) computed
from the boresight's ICRS place (`astro.equatorial`); Altitude/Azimuth the observed
place; SiderealTime the local apparent sidereal time from ERFA at mount time.
"""

from __future__ import annotations

import contextlib
import json
import logging
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any

from virtualstar.astro import EarthOrientation
from virtualstar.astro.constants import SIDEREAL_RATE_ARCSEC_S
from virtualstar.astro.equatorial import icrs_to_j2000, j2000_to_icrs, local_sidereal_time_hours
from virtualstar.vss_client import ServerUnavailable, VssRequestError
from virtualstar.vss_operations import hand_pad_rates, is_moving, is_parked, is_tracking

from .actions import offset_params, track_satellite_params
from .protocol import (
    ACTION_NOT_IMPLEMENTED,
    DRIVER_ERROR,
    INVALID_OPERATION,
    INVALID_VALUE,
    INVALID_WHILE_PARKED,
    NOT_CONNECTED,
    NOT_IMPLEMENTED,
    VALUE_NOT_SET,
    AlpacaError,
    Params,
)

__all__ = ["AlpacaTelescope", "TelescopeOptions"]

log = logging.getLogger("virtualstar.alpaca")

SIDEREAL_DEG_S = SIDEREAL_RATE_ARCSEC_S / 3600.0  # ASCOM's guide rates are in degrees/s
ACTIONS = ("TrackSatellite", "OperationStatus", "Offset")

# VSS error codes → ASCOM error numbers (the VSS message goes along)
_VSS_ERRORS = {"bad_request": INVALID_VALUE, "unreachable": INVALID_VALUE,
               "exclusion_zone": INVALID_VALUE, "stale_tle": INVALID_VALUE,
               "passive": INVALID_OPERATION, "not_tracking": INVALID_OPERATION,
               "mount_offline": NOT_CONNECTED, "forbidden": INVALID_OPERATION,
               "unauthorized": NOT_CONNECTED, "no_camera": INVALID_OPERATION}


@dataclass(frozen=True)
class TelescopeOptions:
    """What the façade says about itself and the optics (None: NotImplemented, honestly)."""

    name: str = "VirtualStar"
    description: str = "VirtualStar alt-az telescope (through the VirtualStar Server)"
    aperture_diameter_m: float | None = None
    aperture_area_m2: float | None = None
    focal_length_m: float | None = None


Handler = Callable[["AlpacaTelescope", Params], Awaitable[Any]]
MEMBERS: dict[tuple[str, str], Handler] = {}
_NEEDS_NO_CONNECTION: set[str] = set()


def member(method: str, name: str, *, disconnected: bool = False):
    """Register a handler for `method` ("GET"/"PUT") of the lower-case member `name`."""
    def register(fn: Handler) -> Handler:
        MEMBERS[(method, name)] = fn
        if disconnected:
            _NEEDS_NO_CONNECTION.add(name)
        return fn
    return register


def constant(name: str, value: Any) -> None:
    """A GET member whose value never changes (capabilities, modes)."""
    async def get(dev: AlpacaTelescope, p: Params) -> Any:
        return value
    member("GET", name, disconnected=True)(get)


def not_implemented(method: str, name: str, why: str) -> None:
    async def refuse(dev: AlpacaTelescope, p: Params) -> Any:
        raise AlpacaError(NOT_IMPLEMENTED, why)
    member(method, name, disconnected=True)(refuse)


class AlpacaTelescope:
    """Telescope device 0: ITelescopeV4 members over a VSS client (anything with `request`)."""

    def __init__(self, vss, options: TelescopeOptions | None = None) -> None:
        self.vss = vss
        self.options = options or TelescopeOptions()
        self.connected = False
        self.target: tuple[float | None, float | None] | None = None  # TargetRA (h), TargetDec
        self.slew_settle_s = 0
        self.guide_rate_ra_deg_s = 0.5 * SIDEREAL_DEG_S
        self.guide_rate_dec_deg_s = 0.5 * SIDEREAL_DEG_S
        self.track_after_move = False  # Tracking was on when the hand pad started
        self.pulse: tuple[int, int] = (0, 0)  # (operation id, end µs) of the latest guide pulse
        self.unparked_op: int | None = None  # the park operation Unpark released
        self.quiet_ops: set[int] = set()  # tracks started to hold the sky still: not slews
        self._eop: EarthOrientation | None = None

    # ------------------------------------------------------------------ plumbing
    async def close(self) -> None:
        """Nothing runs in the background: every request is answered in its own call."""

    async def handle(self, method: str, name: str, params: Params) -> Any:
        """Run one member; raise AlpacaError for the reply, KeyError for an unknown member."""
        handler = MEMBERS[(method, name)]
        if not self.connected and name not in _NEEDS_NO_CONNECTION:
            raise AlpacaError(NOT_CONNECTED, f"{name}: the telescope is not connected; set "
                              "Connected true (or call Connect) first")
        return await handler(self, params)

    @staticmethod
    def knows(name: str) -> bool:
        return name in MEMBER_NAMES

    @staticmethod
    def takes(method: str, name: str) -> bool:
        return (method, name) in MEMBERS

    async def call(self, cmd: str, params: dict[str, Any] | None = None,
                   timeout_s: float | None = 30.0) -> Any:
        """Send a VSS command; turn its refusal into the ASCOM error that says the same."""
        try:
            return await self.vss.request(cmd, params or {}, timeout_s)
        except VssRequestError as exc:
            raise AlpacaError(_VSS_ERRORS.get(exc.code, DRIVER_ERROR),
                              f"{exc.message} [VSS {exc.code}]") from None
        except (ServerUnavailable, TimeoutError) as exc:
            raise AlpacaError(NOT_CONNECTED, f"the VirtualStar Server does not answer: {exc}") \
                from None

    async def begin(self, cmd: str, params: dict[str, Any], *, quiet: bool = False) -> dict:
        """Start an operation; return it once the VSS accepted it (or raise its refusal)."""
        op = await self.call(cmd, {**params, "answer_on_accept": True})
        if quiet:
            self.quiet_ops.add(int(op["id"]))
        return op

    async def track_here(self, st: dict[str, Any], *, quiet: bool = True) -> None:
        """Track the sky where the telescope points (Tracking on; after an abort or a move).

        `quiet`: not a slew (Tracking set on: ASCOM does not count it as one). After an
        abort the track *is* part of stopping: until it has joined the sky and settled,
        RA/Dec still drift, so Slewing stays true (quiet=False).
        """
        await self.begin("track", {"ra_deg": st["radec"]["ra_deg"],
                                   "dec_deg": st["radec"]["dec_deg"]}, quiet=quiet)

    async def status(self) -> dict[str, Any]:
        st = await self.call("status")
        if not st.get("connected") or "mount_time_us" not in st:
            raise AlpacaError(NOT_CONNECTED, "the VirtualStar Server has no mount connected "
                              f"({st.get('mount_error') or 'connecting'})")
        return st

    @property
    def eop(self) -> EarthOrientation:
        if self._eop is None:
            self._eop = EarthOrientation.from_astropy_iers_data()
        return self._eop

    # ------------------------------------------------------------------ state read from the VSS
    @staticmethod
    def _op(st: dict[str, Any]) -> dict[str, Any] | None:
        return st.get("operation")

    def is_tracking(self, st: dict[str, Any]) -> bool:
        return is_tracking(self._op(st))

    def is_slewing(self, st: dict[str, Any]) -> bool:
        op = self._op(st)
        if op is None or op["id"] in self.quiet_ops:
            return False
        return is_moving(op) or self._settling(op, st)

    def _settling(self, op: dict[str, Any], st: dict[str, Any]) -> bool:
        landed = op["info"].get("landed_us")
        return bool(self.slew_settle_s and landed
                    and st["mount_time_us"] < landed + self.slew_settle_s * 1_000_000)

    def move_rates(self, st: dict[str, Any]) -> list[float]:
        """The hand pad's axis rates (deg/s): those of the running VSS move, else zero."""
        return hand_pad_rates(self._op(st))

    def is_pulse_guiding(self, st: dict[str, Any]) -> bool:
        op = self._op(st)
        op_id, end_us = self.pulse
        return op is not None and op["id"] == op_id and st["mount_time_us"] < end_us

    def at_park(self, st: dict[str, Any]) -> bool:
        return is_parked(self._op(st), self.unparked_op)

    async def refuse_if_parked(self, what: str) -> dict[str, Any]:
        st = await self.status()
        if self.at_park(st):
            raise AlpacaError(INVALID_WHILE_PARKED, f"{what}: the telescope is parked; Unpark "
                              "first")
        return st

    def j2000(self, st: dict[str, Any]) -> tuple[float, float]:
        return icrs_to_j2000(st["radec"]["ra_deg"], st["radec"]["dec_deg"])


# ---------------------------------------------------------------------- values checked
def _ra_hours(p: Params, name: str) -> float:
    ra = p.number(name)
    if not 0.0 <= ra < 24.0:
        raise AlpacaError(INVALID_VALUE, f"{name}={ra:g}: expected hours, 0 <= RA < 24")
    return ra


def _dec_deg(p: Params, name: str) -> float:
    dec = p.number(name)
    if not -90.0 <= dec <= 90.0:
        raise AlpacaError(INVALID_VALUE, f"{name}={dec:g}: expected degrees, -90 <= Dec <= 90")
    return dec


def _axis(p: Params) -> int:
    axis = p.integer("Axis")
    if axis not in (0, 1, 2):
        raise AlpacaError(INVALID_VALUE, f"Axis={axis}: expected 0 (primary, azimuth), "
                          "1 (secondary, elevation) or 2 (tertiary)")
    return axis


# ---------------------------------------------------------------------- common members
@member("GET", "connected", disconnected=True)
async def _get_connected(dev: AlpacaTelescope, p: Params) -> Any:
    return dev.connected


@member("PUT", "connected", disconnected=True)
async def _put_connected(dev: AlpacaTelescope, p: Params) -> Any:
    if p.boolean("Connected"):
        await _connect(dev, p)
    else:
        dev.connected = False


@member("PUT", "connect", disconnected=True)
async def _connect(dev: AlpacaTelescope, p: Params) -> Any:
    await dev.status()  # the VSS answers and has its mount: raises NotConnected otherwise
    dev.connected = True


@member("PUT", "disconnect", disconnected=True)
async def _disconnect(dev: AlpacaTelescope, p: Params) -> Any:
    dev.connected = False  # the VSS and the mount carry on; only this client lets go


constant("connecting", False)  # Connect completes before it answers
constant("interfaceversion", 4)
constant("driverversion", "1.0")
constant("supportedactions", list(ACTIONS))


@member("GET", "name", disconnected=True)
async def _name(dev: AlpacaTelescope, p: Params) -> Any:
    return dev.options.name


@member("GET", "description", disconnected=True)
async def _description(dev: AlpacaTelescope, p: Params) -> Any:
    return dev.options.description


@member("GET", "driverinfo", disconnected=True)
async def _driver_info(dev: AlpacaTelescope, p: Params) -> Any:
    return ("VirtualStar Alpaca façade: ITelescopeV4 translated to VirtualStar Server commands "
            "(Sun zone, horizon and one owner of the mount apply)")


for _cmd in ("commandblind", "commandbool", "commandstring"):
    not_implemented("PUT", _cmd, "raw commands are not supported: use SupportedActions "
                    "(Action) or the VirtualStar Server API")


@member("PUT", "action")
async def _action(dev: AlpacaTelescope, p: Params) -> Any:
    name = p.text("Action")
    params = p.get("Parameters") or ""
    if name.lower() == "tracksatellite":
        track = track_satellite_params(params)
        await dev.refuse_if_parked("TrackSatellite")
        return json.dumps(await dev.begin("track", track))
    if name.lower() == "offset":
        return json.dumps(await dev.call("offset", offset_params(params)))
    if name.lower() == "operationstatus":
        return json.dumps(dev._op(await dev.status()))
    raise AlpacaError(ACTION_NOT_IMPLEMENTED, f"action {name!r} is not supported; supported: "
                      f"{', '.join(ACTIONS)}")


@member("GET", "devicestate")
async def _device_state(dev: AlpacaTelescope, p: Params) -> Any:
    st = await dev.status()
    ra, dec = dev.j2000(st)
    values = {"Altitude": st["observed"]["el_deg"], "AtHome": False, "AtPark": dev.at_park(st),
              "Azimuth": st["observed"]["az_deg"] % 360.0, "Declination": dec,
              "IsPulseGuiding": dev.is_pulse_guiding(st),
              "RightAscension": ra / 15.0,
              "SiderealTime": local_sidereal_time_hours(st["mount_time_us"],
                                                        st["site"]["lon_deg"], dev.eop),
              "Slewing": dev.is_slewing(st), "Tracking": dev.is_tracking(st),
              "UTCDate": _utc_text(st["mount_time_utc"]),
              "TimeStamp": _utc_text(st["mount_time_utc"])}
    return [{"Name": k, "Value": v} for k, v in values.items()]


def _utc_text(iso: str) -> str:
    return iso if iso.endswith("Z") else iso + "Z"


# ---------------------------------------------------------------------- capabilities
for _name_, _value in {
        "alignmentmode": 0,  # algAltAz
        "equatorialsystem": 2,  # J2000
        "athome": False, "canfindhome": False, "canpark": True, "canpulseguide": True,
        "cansetdeclinationrate": False, "cansetguiderates": True, "cansetpark": False,
        "cansetpierside": False, "cansetrightascensionrate": False, "cansettracking": True,
        "canslew": False, "canslewasync": True, "canslewaltaz": False, "canslewaltazasync": True,
        "cansync": False, "cansyncaltaz": False, "canunpark": True,
        "trackingrates": [0],  # driveSidereal only
        "rightascensionrate": 0.0, "declinationrate": 0.0}.items():
    constant(_name_, _value)

not_implemented("PUT", "rightascensionrate", "RightAscensionRate cannot be set: the VSS "
                "tracks sidereal targets (CanSetRightAscensionRate is false)")
not_implemented("PUT", "declinationrate", "DeclinationRate cannot be set (CanSetDeclinationRate "
                "is false)")
not_implemented("GET", "sideofpier", "an alt-az mount has no pier side")
not_implemented("PUT", "sideofpier", "an alt-az mount has no pier side")
not_implemented("GET", "destinationsideofpier", "an alt-az mount has no pier side")
not_implemented("PUT", "findhome", "the direct-drive axes have absolute encoders: no homing "
                "(CanFindHome is false)")
not_implemented("PUT", "setpark", "the park position is the mount mapping's (CanSetPark is false)")
for _slew in ("slewtocoordinates", "slewtotarget", "slewtoaltaz"):
    not_implemented("PUT", _slew, "synchronous slews are not offered through Alpaca (the ASCOM "
                    "slew FAQ: CanSlew and CanSlewAltAz are false); use the *Async member and "
                    "poll Slewing")
for _sync in ("synctocoordinates", "synctoaltaz", "synctotarget"):
    not_implemented("PUT", _sync, "VirtualStar corrects pointing with a fitted pointing model "
                    "(vs pointing-run, pointing-model fit), not with syncs (CanSync is false)")


def _optics(name: str, attribute: str, what: str) -> None:
    @member("GET", name, disconnected=True)
    async def get(dev: AlpacaTelescope, p: Params) -> Any:
        value = getattr(dev.options, attribute)
        if value is None:
            raise AlpacaError(NOT_IMPLEMENTED, f"{what} is not configured (vs alpaca "
                              f"--{attribute.replace('_', '-')})")
        return value


_optics("aperturediameter", "aperture_diameter_m", "the aperture diameter")
_optics("aperturearea", "aperture_area_m2", "the aperture area")
_optics("focallength", "focal_length_m", "the focal length")


@member("GET", "axisrates", disconnected=True)
async def _axis_rates(dev: AlpacaTelescope, p: Params) -> Any:
    axis = _axis(p)
    if axis == 2:
        return []
    limits = (await dev.call("status")).get("limits") or {}
    top = limits.get("az_max_rate_deg_s" if axis == 0 else "el_max_rate_deg_s", 0.0)
    return [{"Maximum": top, "Minimum": 0.0}]


@member("GET", "canmoveaxis", disconnected=True)
async def _can_move_axis(dev: AlpacaTelescope, p: Params) -> Any:
    return _axis(p) in (0, 1)


# ---------------------------------------------------------------------- where it points
@member("GET", "altitude")
async def _altitude(dev: AlpacaTelescope, p: Params) -> Any:
    return (await dev.status())["observed"]["el_deg"]


@member("GET", "azimuth")
async def _azimuth(dev: AlpacaTelescope, p: Params) -> Any:
    return (await dev.status())["observed"]["az_deg"] % 360.0


@member("GET", "rightascension")
async def _ra(dev: AlpacaTelescope, p: Params) -> Any:
    return dev.j2000(await dev.status())[0] / 15.0


@member("GET", "declination")
async def _dec(dev: AlpacaTelescope, p: Params) -> Any:
    return dev.j2000(await dev.status())[1]


@member("GET", "siderealtime")
async def _sidereal(dev: AlpacaTelescope, p: Params) -> Any:
    st = await dev.status()
    return local_sidereal_time_hours(st["mount_time_us"], st["site"]["lon_deg"], dev.eop)


@member("GET", "utcdate")
async def _utc(dev: AlpacaTelescope, p: Params) -> Any:
    return _utc_text((await dev.status())["mount_time_utc"])


not_implemented("PUT", "utcdate", "the mount's clock is disciplined by its 1 PPS and the "
                "VSS's time sync; it is not set by clients")


def _site(name: str, param: str, key: str, lo: float, hi: float) -> None:
    @member("GET", name)
    async def get(dev: AlpacaTelescope, p: Params) -> Any:
        return (await dev.call("status"))["site"][key]

    @member("PUT", name)
    async def put(dev: AlpacaTelescope, p: Params) -> Any:
        value = p.number(param)
        if not lo <= value <= hi:
            raise AlpacaError(INVALID_VALUE, f"{param}={value:g}: expected {lo:g}..{hi:g}")
        raise AlpacaError(NOT_IMPLEMENTED, "the site is the VirtualStar Server's (its --site "
                          "file); clients cannot move it")


_site("sitelatitude", "SiteLatitude", "lat_deg", -90.0, 90.0)
_site("sitelongitude", "SiteLongitude", "lon_deg", -180.0, 180.0)
_site("siteelevation", "SiteElevation", "height_m", -300.0, 10000.0)


@member("GET", "doesrefraction")
async def _refraction(dev: AlpacaTelescope, p: Params) -> Any:
    return (await dev.call("status"))["site"]["pressure_hpa"] > 0.0


not_implemented("PUT", "doesrefraction", "refraction follows the site's weather (pressure 0 "
                "turns it off in the VSS's site file)")


# ---------------------------------------------------------------------- state
@member("GET", "atpark")
async def _at_park(dev: AlpacaTelescope, p: Params) -> Any:
    return dev.at_park(await dev.status())


@member("GET", "slewing")
async def _slewing(dev: AlpacaTelescope, p: Params) -> Any:
    return dev.is_slewing(await dev.status())


@member("GET", "tracking")
async def _tracking(dev: AlpacaTelescope, p: Params) -> Any:
    return dev.is_tracking(await dev.status())


@member("PUT", "tracking")
async def _set_tracking(dev: AlpacaTelescope, p: Params) -> Any:
    on = p.boolean("Tracking")
    st = await dev.status()
    if on == dev.is_tracking(st):
        return
    if not on:
        await dev.call("stop")
        return
    if dev.at_park(st):
        raise AlpacaError(INVALID_WHILE_PARKED, "Tracking: the telescope is parked; Unpark first")
    await dev.track_here(st)


@member("GET", "trackingrate")
async def _tracking_rate(dev: AlpacaTelescope, p: Params) -> Any:
    return 0


@member("PUT", "trackingrate")
async def _set_tracking_rate(dev: AlpacaTelescope, p: Params) -> Any:
    rate = p.integer("TrackingRate")
    if rate != 0:
        raise AlpacaError(INVALID_VALUE, f"TrackingRate={rate}: only 0 (driveSidereal) is "
                          "supported (TrackingRates)")


@member("GET", "ispulseguiding")
async def _is_guiding(dev: AlpacaTelescope, p: Params) -> Any:
    return dev.is_pulse_guiding(await dev.status())


def _stored(name: str, param: str, attribute: str, check: Callable[[float], bool],
            expected: str, *, integer: bool = False) -> None:
    @member("GET", name)
    async def get(dev: AlpacaTelescope, p: Params) -> Any:
        return getattr(dev, attribute)

    @member("PUT", name)
    async def put(dev: AlpacaTelescope, p: Params) -> Any:
        value = p.integer(param) if integer else p.number(param)
        if not check(value):
            raise AlpacaError(INVALID_VALUE, f"{param}={value:g}: expected {expected}")
        setattr(dev, attribute, value)


_stored("slewsettletime", "SlewSettleTime", "slew_settle_s", lambda v: 0 <= v <= 600,
        "0..600 seconds", integer=True)
_stored("guideraterightascension", "GuideRateRightAscension", "guide_rate_ra_deg_s",
        lambda v: 0 < v <= 10 * SIDEREAL_DEG_S, "degrees per second, above 0, at most 10× sidereal")
_stored("guideratedeclination", "GuideRateDeclination", "guide_rate_dec_deg_s",
        lambda v: 0 < v <= 10 * SIDEREAL_DEG_S, "degrees per second, above 0, at most 10× sidereal")


# ---------------------------------------------------------------------- targets and slews
@member("GET", "targetrightascension")
async def _target_ra(dev: AlpacaTelescope, p: Params) -> Any:
    if dev.target is None or dev.target[0] is None:
        raise AlpacaError(VALUE_NOT_SET, "TargetRightAscension has not been set")
    return dev.target[0]


@member("GET", "targetdeclination")
async def _target_dec(dev: AlpacaTelescope, p: Params) -> Any:
    if dev.target is None or dev.target[1] is None:
        raise AlpacaError(VALUE_NOT_SET, "TargetDeclination has not been set")
    return dev.target[1]


@member("PUT", "targetrightascension")
async def _set_target_ra(dev: AlpacaTelescope, p: Params) -> Any:
    ra = _ra_hours(p, "TargetRightAscension")
    dev.target = (ra, dev.target[1] if dev.target else None)  # type: ignore[assignment]


@member("PUT", "targetdeclination")
async def _set_target_dec(dev: AlpacaTelescope, p: Params) -> Any:
    dec = _dec_deg(p, "TargetDeclination")
    dev.target = (dev.target[0] if dev.target else None, dec)  # type: ignore[assignment]


async def _slew_radec(dev: AlpacaTelescope, ra_h: float, dec_deg: float) -> None:
    st = await dev.refuse_if_parked("SlewToCoordinatesAsync")
    if not dev.is_tracking(st):
        raise AlpacaError(INVALID_OPERATION, "SlewToCoordinatesAsync: Tracking is off; set "
                          "Tracking true first (an equatorial target is tracked once reached)")
    ra, dec = j2000_to_icrs(ra_h * 15.0, dec_deg)
    dev.target = (ra_h, dec_deg)
    await dev.begin("slew", {"ra_deg": ra, "dec_deg": dec})


@member("PUT", "slewtocoordinatesasync")
async def _slew_coords_async(dev: AlpacaTelescope, p: Params) -> Any:
    await _slew_radec(dev, _ra_hours(p, "RightAscension"), _dec_deg(p, "Declination"))


def _target_or_refuse(dev: AlpacaTelescope) -> tuple[float, float]:
    if dev.target is None or None in dev.target:
        raise AlpacaError(VALUE_NOT_SET, "set TargetRightAscension and TargetDeclination first")
    return dev.target  # type: ignore[return-value]


@member("PUT", "slewtotargetasync")
async def _slew_target_async(dev: AlpacaTelescope, p: Params) -> Any:
    await _slew_radec(dev, *_target_or_refuse(dev))


@member("PUT", "slewtoaltazasync")
async def _slew_altaz_async(dev: AlpacaTelescope, p: Params) -> Any:
    az, alt = p.number("Azimuth"), p.number("Altitude")
    if not 0.0 <= az < 360.0:
        raise AlpacaError(INVALID_VALUE, f"Azimuth={az:g}: expected 0 <= Azimuth < 360 degrees")
    if not -90.0 <= alt <= 90.0:
        raise AlpacaError(INVALID_VALUE, f"Altitude={alt:g}: expected -90..90 degrees")
    st = await dev.refuse_if_parked("SlewToAltAzAsync")
    if dev.is_tracking(st):
        raise AlpacaError(INVALID_OPERATION, "SlewToAltAzAsync: Tracking is on; set Tracking "
                          "false first (an alt-az place is held, not tracked)")
    await dev.begin("slew", {"az_deg": az, "el_deg": alt})


@member("PUT", "abortslew")
async def _abort(dev: AlpacaTelescope, p: Params) -> Any:
    """Stop a slew or a hand-pad move; tracking returns to what it was before (ASCOM).

    With tracking, the mount comes to rest and then tracks the sky where it stopped;
    Slewing stays true until that track has joined the sky and settled (the VSS's
    arrival check: within 5″), so RA/Dec hold still once Slewing reads false.
    """
    st = await dev.refuse_if_parked("AbortSlew")
    if not dev.is_slewing(st):
        return  # nothing moves: nothing to abort (tracking goes on)
    op = dev._op(st) or {}
    resume = (dev.track_after_move if op.get("kind") == "move"
              else dev.is_tracking(st))  # an equatorial slew needed Tracking on
    await dev.call("stop")
    if resume:
        await dev.track_here(await dev.status(), quiet=False)


@member("PUT", "park")
async def _park(dev: AlpacaTelescope, p: Params) -> Any:
    st = await dev.status()
    if dev.at_park(st):
        return
    await dev.call("park", {"wait": False})
    dev.unparked_op = None


@member("PUT", "unpark")
async def _unpark(dev: AlpacaTelescope, p: Params) -> Any:
    op = dev._op(await dev.status())
    if op is not None and op["kind"] == "park":
        dev.unparked_op = op["id"]


# ---------------------------------------------------------------------- hand pad and guiding
@member("PUT", "moveaxis")
async def _move_axis(dev: AlpacaTelescope, p: Params) -> Any:
    axis = _axis(p)
    rate = p.number("Rate")
    if axis == 2:
        raise AlpacaError(NOT_IMPLEMENTED, "an alt-az mount has no tertiary axis "
                          "(CanMoveAxis(2) is false)")
    st = await dev.refuse_if_parked("MoveAxis")
    top = st["limits"]["az_max_rate_deg_s" if axis == 0 else "el_max_rate_deg_s"]
    if abs(rate) > top:
        raise AlpacaError(INVALID_VALUE, f"Rate={rate:g}: beyond AxisRates ±{top:g} deg/s")
    before = dev.move_rates(st)
    rates = list(before)
    rates[axis] = rate
    if rates == before:
        return  # e.g. MoveAxis(axis, 0) with nothing moving
    if before == [0.0, 0.0]:
        dev.track_after_move = dev.is_tracking(st)
    if rates != [0.0, 0.0]:
        # answered once the axes move: a refusal (a limit, a zone) comes back here
        await dev.call("move", {"az_rate_deg_s": rates[0], "el_rate_deg_s": rates[1]}, None)
        return
    await dev.call("stop")
    if dev.track_after_move:  # tracking resumes where the hand pad left the telescope
        await dev.track_here(await dev.status())


_GUIDE = {0: (1.0, 0.0), 1: (-1.0, 0.0), 2: (0.0, 1.0), 3: (0.0, -1.0)}  # north, east signs


@member("PUT", "pulseguide")
async def _pulse_guide(dev: AlpacaTelescope, p: Params) -> Any:
    direction = p.integer("Direction")
    duration_ms = p.integer("Duration")
    if direction not in _GUIDE:
        raise AlpacaError(INVALID_VALUE, f"Direction={direction}: expected 0 (north), 1 (south), "
                          "2 (east) or 3 (west)")
    if not 0 <= duration_ms <= 600_000:
        raise AlpacaError(INVALID_VALUE, f"Duration={duration_ms}: expected 0..600000 ms")
    st = await dev.refuse_if_parked("PulseGuide")
    if not dev.is_tracking(st):
        raise AlpacaError(INVALID_OPERATION, "PulseGuide: the telescope is not tracking; guide "
                          "pulses offset a track")
    if duration_ms == 0:
        return
    north, east = _GUIDE[direction]
    rate_deg_s = dev.guide_rate_dec_deg_s if north else dev.guide_rate_ra_deg_s
    size_arcsec = rate_deg_s * 3600.0 * duration_ms / 1000.0
    pulse = await dev.call("guide", {"north_arcsec": north * size_arcsec,
                                     "east_arcsec": east * size_arcsec,
                                     "rate_arcsec_s": rate_deg_s * 3600.0})
    op_id, end_us = dev.pulse
    if op_id != pulse["id"]:
        end_us = 0
    dev.pulse = (int(pulse["id"]), max(end_us, int(pulse["end_us"])))


with contextlib.suppress(NameError):
    del _cmd, _name_, _value, _sync, _slew

MEMBER_NAMES = frozenset(name for _method, name in MEMBERS)
