"""Start the bundled mount emulator inside this process (`vs server --emulator`, `vs demo`).

This is the only module of `virtualstar` that imports `mount_emulator` and the guide
camera simulator `guide_camera` (docs/architecture.md): everything else talks to a
mount or a camera through ASTCom only.
"""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["DEFAULT_ENDPOINT_PORT", "CameraSim", "EmbeddedCamera", "EmbeddedEmulator",
           "EmbeddedVss", "EndpointUnavailable", "camera_from_file", "embedded_vss",
           "hidden_geometry_arcsec", "satellite_camera", "star_camera", "start_emulator",
           "start_guide_camera"]

# `vs server --emulator` serves its emulator's ASTCom endpoint on this port unless told
# otherwise, so that after a restart clients (the panel) find it where it was: beside the
# VSS's own 8740.
DEFAULT_ENDPOINT_PORT = 8741
IN_MEMORY_QUEUE = 256  # frames in flight per direction of an in-process connection
# A request over an in-process connection is answered by a task of the same event loop: no
# network can lose it, so its wall-clock deadline only measures how starved the host is. At
# 5 s (a socket's) a lockstep run on a loaded host (a 4-worker suite beside other jobs) took
# a slow answer for a lost mount ("lost the connection to the mount") and faulted the
# operation; a hung peer is still found, later.
IN_MEMORY_TIMEOUT_S = 30.0
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
                                timeout_s: float = IN_MEMORY_TIMEOUT_S):
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


@dataclass(frozen=True)
class CameraSim:
    """A simulated guide camera to run beside the embedded emulator: its truth and settings.

    `truth` is a `guide_camera` truth (`SatelliteTruth`, `StarTruth`); `config` a
    `guide_camera.CameraConfig` (None: its defaults). Build one with `satellite_camera`
    or `star_camera`.
    """

    truth: Any
    config: Any = None


def satellite_camera(line1: str, line2: str, site: Any, *, along_s: float = 0.0,
                     across_arcsec: float = 0.0, at_us: int | None = None,
                     config: Any = None) -> CameraSim:
    """A camera that sees a satellite whose true elements are the given ones moved
    `along_s` along its track and `across_arcsec` across it at `at_us` (guide_camera's
    `shifted_tle`); the VSS is given the unmoved ones."""
    from guide_camera import CameraSite, SatelliteTruth, shifted_elements

    where = CameraSite.from_object(site)
    if not (along_s or across_arcsec):
        return CameraSim(SatelliteTruth(line1, line2, where), config)
    if at_us is None:
        raise ValueError("a moved satellite needs the time its offsets are seen at (at_us)")
    elements = shifted_elements(line1, line2, along_s=along_s, across_arcsec=across_arcsec,
                                at_us=at_us, site=where)
    return CameraSim(SatelliteTruth.from_satrec(elements, where), config)


def star_camera(ra_deg: float, dec_deg: float, site: Any, *, config: Any = None,
                **motion: float) -> CameraSim:
    """A camera that sees a star at its catalogue place (pm_ra_cosdec_mas_yr, pm_dec_mas_yr,
    parallax_mas, rv_km_s, epoch_jyear as keywords)."""
    from guide_camera import CameraSite, StarTruth

    return CameraSim(StarTruth(ra_deg, dec_deg, CameraSite.from_object(site), **motion), config)


def camera_from_file(path: str | Path, site: Any) -> CameraSim:
    """A simulated camera from a TOML file (guide_camera's `load_camera_file` layout); the
    [truth] table may also name a bundled star: star = "Vega"."""
    from catalogs import UnknownStar, bright_stars
    from guide_camera import CameraConfigError, CameraSite
    from guide_camera.config_file import camera_config, read_camera_file, truth_from_table

    where = CameraSite.from_object(site)
    try:
        doc = read_camera_file(path)
        truth = dict(doc["truth"])
        if "star" in truth:
            try:
                star = bright_stars().lookup(str(truth.pop("star")))
            except UnknownStar as exc:
                raise ValueError(f"{path}: {exc}") from None
            truth.update(ra_deg=star.ra_deg, dec_deg=star.dec_deg,
                         pm_ra_cosdec_mas_yr=star.pm_ra_cosdec_mas_yr,
                         pm_dec_mas_yr=star.pm_dec_mas_yr, parallax_mas=star.parallax_mas,
                         rv_km_s=star.rv_km_s or 0.0, epoch_jyear=star.epoch_jyear)
        return CameraSim(truth_from_table(truth, where, Path(path)),
                         camera_config(doc.get("camera", {}), path))
    except CameraConfigError as exc:
        raise ValueError(str(exc)) from None


@dataclass
class EmbeddedCamera:
    """A running simulated guide camera: its device and where clients reach it."""

    url: str
    device: Any

    async def connect_in_memory(self, *, name: str = "in-process", password: str | None = None,
                                timeout_s: float = IN_MEMORY_TIMEOUT_S):
        from astcom_client import Client

        end = self.device.endpoint.connect_in_memory(IN_MEMORY_QUEUE)
        return await Client.open(end, password=password, name=name, timeout_s=timeout_s)

    async def stop(self) -> None:
        await self.device.stop()


async def start_guide_camera(emulator: EmbeddedEmulator, sim: CameraSim, *, site: Any = None,
                             clock: Any = None, url: str | None = "ws://127.0.0.1:0",
                             password: str | None = None,
                             observer_password: str | None = None) -> EmbeddedCamera:
    """Start the guide camera simulator beside an embedded emulator (same event loop).

    It reads the emulator through an in-memory ASTCom connection and waits on `clock`
    (the lockstep clock: deterministic frames), or follows the emulator's own clock.
    `url` also serves the camera on a socket (the panel, the recorder; None: nowhere);
    `password` (the emulator's operator password) and `observer_password` guard it too.
    """
    from guide_camera import CameraConfig, CameraSite, GuideCameraDevice

    async def connect():
        return await emulator.connect_in_memory(password=password, name="guide-camera")

    passwords = {role: pw for role, pw in (("operator", password),
                                           ("observer", observer_password)) if pw} or None
    device = GuideCameraDevice(connect, sim.truth, config=sim.config or CameraConfig(),
                               site=None if site is None else CameraSite.from_object(site),
                               clock=clock, passwords=passwords)
    bound = await device.start(url)
    return EmbeddedCamera(bound, device)


@dataclass
class EmbeddedVss:
    """A VSS driving an in-process emulator: both parts, and where clients connect."""

    emulator: EmbeddedEmulator
    server: Any  # virtualstar.server.VssServer
    url: str  # the VSS's WebSocket URL ('' when it listens nowhere)
    camera: EmbeddedCamera | None = None

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
                       camera: CameraSim | None = None,
                       camera_url: str | None = None,
                       **server_options: Any) -> AsyncIterator[EmbeddedVss]:
    """Run the emulator and a VSS driving it on this event loop, until the block ends.

    With a `LockstepClock` (lockstep simulated time) the VSS reaches the emulator
    through an in-memory ASTCom connection; otherwise through `emulator_url` at
    `speed`. `listen` (ws://HOST:PORT) also serves the VSS API on a socket. The block
    starts once the VSS is connected and has its first tracking-error samples.
    `password` (the VSS uses it) and `observer_password` guard the emulator's endpoint.
    `camera` runs a simulated guide camera beside the emulator (served on `camera_url`
    too, if given) and gives it to the VSS for closed loops.
    """
    from virtualstar.server import build_server
    from virtualstar.server.camera_link import CameraLinkConfig

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
    cam = None
    try:  # from here on the emulator runs: it stops however the block ends, a refused set-up too
        server_options.setdefault("mount_endpoint", emu.url)  # told to clients (status, hello)
        link = None
        if camera is not None:
            from virtualstar.astro import load_site

            cam = await start_guide_camera(emu, camera, site=site or load_site(), clock=clock,
                                           url=camera_url, password=password,
                                           observer_password=observer_password)

            async def camera_connector():
                return await cam.connect_in_memory(name="virtualstar-server", password=password)

            link = CameraLinkConfig(cam.url or "in-process guide camera",
                                    connector=camera_connector)
        server = build_server(mount_url=emu.url if clock is None else "in-process emulator",
                              password=password, speed=speed, site=site, clock=clock,
                              connector=connector, camera=link, **server_options)
        url = await server.start(listen)
        await server.telescope.link.wait_connected(connect_timeout_s)
        await server.telescope.first_samples(connect_timeout_s)
        yield EmbeddedVss(emu, server, url, cam)
    finally:
        if server is not None:
            await server.close()
        if cam is not None:
            await cam.stop()
        await emu.stop()
