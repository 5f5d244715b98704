"""Start the bundled mount emulator inside this process (`vs server --emulator`, `vs demo`).

This is the only module of `virtualstar` that imports `mount_emulator`
(docs/architecture.md): everything else talks to a mount through ASTCom only.
"""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["DEFAULT_ENDPOINT_PORT", "EmbeddedEmulator", "EmbeddedVss", "EndpointUnavailable",
           "embedded_vss", "hidden_geometry_arcsec", "start_emulator"]

# `vs server --emulator` serves its emulator's ASTCom endpoint on this port unless told
# otherwise, so that after a restart clients (the panel) find it where it was: beside the
# VSS's own 8740.
DEFAULT_ENDPOINT_PORT = 8741
IN_MEMORY_QUEUE = 256  # frames in flight per direction of an in-process connection
LOCKSTEP_STREAM_FLUSH_S = 0.2  # mount seconds of samples per stream packet in lockstep


class EndpointUnavailable(OSError):
    """The embedded emulator's ASTCom endpoint cannot listen where it was asked to."""


@dataclass
class EmbeddedEmulator:
    """A running in-process emulator: its ASTCom URL and the object (to stop it).

    In lockstep (`clock` given to `start_emulator`) the VSS reaches it through
    `connect_in_memory()`: no socket, so nothing the kernel schedules sits between
    the two (the run is deterministic); `url` still serves outside clients.
    """

    url: str
    emulator: Any
    _memory_ends: list[Any] = field(default_factory=list)

    @property
    def mount_time_us(self) -> int:
        return int(self.emulator.model.mount_time_us)

    async def connect_in_memory(self, *, password: str | None = None, name: str = "in-process",
                                timeout_s: float = 5.0):
        """Return an ASTCom `Client` joined to the emulator's endpoint in this process."""
        from astcom_client import Client

        end = self.emulator.endpoint.connect_in_memory(IN_MEMORY_QUEUE)
        self._memory_ends = [e for e in self._memory_ends if not e.closed] + [end]
        return await Client.open(end, password=password, name=name, timeout_s=timeout_s)

    async def cut_in_memory(self) -> None:
        """Break every in-process connection, as a failed network would (tests)."""
        ends, self._memory_ends = self._memory_ends, []
        for end in ends:
            await end.close(1006, "line cut")

    async def stop(self) -> None:
        await self.emulator.stop()


def hidden_geometry_arcsec(*, path: str | Path | None = None,
                           seed: int | None = None) -> dict[str, float]:
    """Return the emulator's hidden TPOINT terms (arcsec) from a TOML/JSON file or a seed.

    The same rules as `mount-emulator --geometry FILE | --seed N`. Raises ValueError
    naming the file or the option when it cannot be used.
    """
    from mount_emulator import Geometry
    from mount_emulator.exceptions import ConfigError

    if path is not None and seed is not None:
        raise ValueError("give either a geometry file or a seed, not both")
    try:
        geometry = Geometry.from_file(path) if path is not None else Geometry.from_seed(int(seed or 0))
    except ConfigError as exc:
        raise ValueError(str(exc)) from None
    return geometry.as_dict()


async def start_emulator(*, speed: float = 1.0, start_us: int | None = None,
                         url: str = "ws://127.0.0.1:0", az_deg: float = 0.0, el_deg: float = 20.0,
                         params: dict[str, float] | None = None,
                         password: str | None = None,
                         observer_password: str | None = None,
                         geometry_arcsec: dict[str, float] | None = None,
                         seeing_arcsec: float | None = None,
                         clock: Any = None) -> EmbeddedEmulator:
    """Start the emulator on this event loop and return where it listens.

    speed: 1 real time, X times real time (simulated time); start_us: mount time at
    start (µs since 1970 UTC, None = now); geometry_arcsec: the hidden TPOINT terms
    ({"ia": 120.0, ...}, default perfect); seeing_arcsec: guide-camera noise.
    clock: a `virtualstar.lockstep.LockstepClock` on this loop: the emulator then
    runs no loop of its own, starts at the clock's time and computes its ticks when
    the clock steps (lockstep simulated time; `speed` is ignored).
    """
    from mount_emulator import EmulatorConfig, Geometry, MountEmulator, MountModel

    # compile (or load) the step before the emulator takes its start time: in real time
    # its clock then starts within milliseconds of UTC, not a compile later
    MountModel(start_us=0).run(0)

    extra = {}
    if geometry_arcsec:
        extra["geometry"] = Geometry.from_mapping(geometry_arcsec, where="geometry_arcsec")
    if seeing_arcsec is not None:
        extra["seeing_arcsec"] = seeing_arcsec
    if clock is not None:
        start_us = clock.now_us
        # in lockstep nobody waits for a packet in wall time: fewer, longer packets
        extra["stream_flush_s"] = LOCKSTEP_STREAM_FLUSH_S
    if observer_password and not password:
        raise ValueError("an observer password needs an operator password too")
    passwords = {role: pw for role, pw in (("operator", password),
                                           ("observer", observer_password)) if pw}
    config = EmulatorConfig(speed=speed, start_us=start_us, az_deg=az_deg, el_deg=el_deg,
                            params=dict(params or {}), passwords=passwords or None, **extra)
    emulator = MountEmulator(config)
    try:
        bound = await emulator.start(url, run_loop=clock is None)
    except OSError as exc:
        raise EndpointUnavailable(exc.errno, f"the emulator's ASTCom endpoint cannot listen on "
                                  f"{url}: {exc.strerror or exc}") from None
    if clock is not None:
        clock.add_driver(emulator.run_until)
    return EmbeddedEmulator(bound, emulator)


@dataclass
class EmbeddedVss:
    """A VSS driving an in-process emulator: both parts, and where clients connect."""

    emulator: EmbeddedEmulator
    server: Any  # virtualstar.server.VssServer
    url: str  # the VSS's WebSocket URL ('' when it listens nowhere)

    def client(self):
        """Return an in-process API client (`LocalVssClient`) of the VSS."""
        from virtualstar.server.local_client import LocalVssClient

        return LocalVssClient(self.server)


@contextlib.asynccontextmanager
async def embedded_vss(*, clock: Any = None, speed: float = 1.0, start_us: int | None = None,
                       site: Any = None, listen: str | None = None,
                       password: str | None = None, observer_password: str | None = None,
                       emulator_url: str = "ws://127.0.0.1:0",
                       geometry_arcsec: dict[str, float] | None = None,
                       seeing_arcsec: float | None = None,
                       emulator_params: dict[str, float] | None = None,
                       connect_timeout_s: float = 30.0,
                       **server_options: Any) -> AsyncIterator[EmbeddedVss]:
    """Run the emulator and a VSS driving it on this event loop, until the block ends.

    With a `LockstepClock` (lockstep simulated time) the VSS reaches the emulator
    through an in-memory ASTCom connection; otherwise through `emulator_url` at
    `speed`. `listen` (ws://HOST:PORT) also serves the VSS API on a socket. The block
    starts once the VSS is connected and has its first tracking-error samples.
    `password` (the VSS uses it) and `observer_password` guard the emulator's endpoint.
    """
    from virtualstar.server import build_server

    emu = await start_emulator(speed=speed, start_us=start_us, url=emulator_url,
                               params=emulator_params, password=password,
                               observer_password=observer_password,
                               geometry_arcsec=geometry_arcsec, seeing_arcsec=seeing_arcsec,
                               clock=clock)
    connector = None
    if clock is not None:
        async def connector():
            return await emu.connect_in_memory(password=password, name="virtualstar-server")
    server = None
    try:  # from here on the emulator runs: it stops however the block ends, a refused set-up too
        server_options.setdefault("mount_endpoint", emu.url)  # told to clients (status, hello)
        server = build_server(mount_url=emu.url if clock is None else "in-process emulator",
                              password=password, speed=speed, site=site, clock=clock,
                              connector=connector, **server_options)
        url = await server.start(listen)
        await server.telescope.link.wait_connected(connect_timeout_s)
        await server.telescope.first_samples(connect_timeout_s)
        yield EmbeddedVss(emu, server, url)
    finally:
        if server is not None:
            await server.close()
        await emu.stop()
