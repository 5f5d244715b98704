"""The one mount-link interface: what the VSS asks of any mount, and what a mount says it can do.

Every backend (ASTCom with a trajectory buffer, ASCOM Alpaca, INDI) implements
`MountBackend`: the VSS speaks to it in *roles* (``az_position``, ``mount_state``,
``slew``, ``stop``…, listed in `mapping.py`), and reads its `MountCapabilities` to
choose how to follow a target, never its type (libindi's capability flags and
ASCOM's ``Can*`` properties are the models):

* ``trajectory_buffer``: the mount takes timed points (``traj_*`` roles) and follows
  them itself; the VSS keeps the buffer filled (`feeder.py`).
* ``rate_axes``: the mount turns each native axis at a commanded rate (``set_rates``);
  the VSS closes the loop on the reported position (`rate_loop.py`).
* ``goto``: the mount slews to a place by itself (``slew``); a mount with only this
  can be pointed, not made to follow anything faster than its own tracking.
* ``park``, ``guide`` (pulses), ``time_sync`` (the PPS clock roles),
  ``error_stream`` (the mount streams its own following error at its loop rate).

The geometry says which native axes the mount turns: ``altaz`` (azimuth, elevation),
``german`` (hour angle, declination, with a pier side and a meridian flip) or ``fork``
(equatorial without a flip). Positions in roles stay observed azimuth and elevation
(radians) whatever the geometry; the native axes are read with the
``axis1_position``/``axis2_position`` roles (for equatorial mounts right ascension and
declination of date) and turned with ``set_rates``.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from typing import Any, Protocol

from .exceptions import MountUnavailable

__all__ = ["GEOMETRIES", "ConnectionWaits", "MountBackend", "MountCapabilities"]

GEOMETRIES = ("altaz", "german", "fork")


@dataclass(frozen=True)
class MountCapabilities:
    """What a mount can do, as its backend learnt it from the driver (see the module doc)."""

    backend: str  # "astcom", "alpaca", "indi"
    geometry: str = "altaz"
    trajectory_buffer: bool = False
    rate_axes: bool = False
    goto: bool = True
    park: bool = True
    guide: bool = False
    time_sync: bool = False
    error_stream: bool = False
    max_rate_deg_s: float | None = None  # the largest axis rate the driver accepts
    rate_step_arcsec_s: float | None = None  # the resolution of a commanded rate
    tracks_sidereal: bool = False  # the mount's own sidereal tracking can be switched on
    goto_tolerance_arcsec: float | None = None  # a goto lands within this (None: exactly)

    def __post_init__(self) -> None:
        if self.geometry not in GEOMETRIES:
            raise ValueError(f"geometry {self.geometry!r}: expected one of {', '.join(GEOMETRIES)}")

    @property
    def equatorial(self) -> bool:
        return self.geometry in ("german", "fork")

    @property
    def native_axes(self) -> tuple[str, str]:
        return ("ra", "dec") if self.equatorial else ("az", "el")

    def as_dict(self) -> dict[str, Any]:
        return {**asdict(self), "native_axes": list(self.native_axes)}


class MountBackend(Protocol):
    """The mount link as the VSS uses it (`mount_link.MountLink` is the ASTCom one)."""

    config: Any  # has .url (the mount's address, for messages)
    mapping: Any  # a `RoleMapping`: state codes, park place, which roles exist
    on_event: Callable[[str, dict[str, Any]], None]
    calls: Any  # the functions called, with the operation that called them
    connects: int
    last_error: str

    @property
    def connected(self) -> bool: ...

    @property
    def capabilities(self) -> MountCapabilities: ...

    def start(self) -> None: ...

    async def stop(self) -> None: ...

    async def wait_connected(self, timeout_s: float | None = None) -> None: ...

    async def wait_reconnected(self, connects_before: int, timeout_s: float) -> None: ...

    def mark_lost(self) -> None: ...

    async def read(self, roles: Sequence[str]) -> dict[str, Any]: ...

    async def call(self, role: str, *args: Any) -> Any: ...

    def scale(self, role: str) -> float: ...

    def describe(self) -> dict[str, Any]:
        """The backend's part of `status`: capabilities, reports (rate, age), what it measured."""
        ...


class ConnectionWaits:
    """Waiting for a mount link's (re)connection, shared by every link that keeps
    `_connected` (an Event), `_changed` (a Condition notified on each change), `connected`,
    `connects` (how many connections so far), `config.url` and `last_error`."""

    _connected: asyncio.Event
    _changed: asyncio.Condition
    connects: int
    last_error: str

    async def wait_connected(self, timeout_s: float | None = None) -> None:
        """Wait until the mount is connected; raise MountUnavailable after `timeout_s`."""
        try:
            async with asyncio.timeout(timeout_s):
                await self._connected.wait()
        except TimeoutError:
            raise MountUnavailable(f"no connection to the mount at {self.config.url} "
                                   f"({self.last_error or 'still trying'})") from None

    async def wait_reconnected(self, connects_before: int, timeout_s: float) -> None:
        """Wait for a connection newer than the `connects_before`-th; MountUnavailable after
        `timeout_s`."""
        async def newer() -> None:
            async with self._changed:
                await self._changed.wait_for(
                    lambda: self.connected and self.connects > connects_before)

        try:
            async with asyncio.timeout(timeout_s):
                await newer()
        except TimeoutError:
            raise MountUnavailable(f"the mount at {self.config.url} did not come back within "
                                   f"{timeout_s:g} s ({self.last_error or 'still trying'})") from None
