"""Put a VSS together from plain options (the one place defaults meet)."""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

from virtualstar.astro import Site, load_site

from .access import AccessConfig
from .backends import is_rate_mount_url, open_rate_mount
from .camera_link import CameraLink, CameraLinkConfig
from .clock import MountClock, PacedClock
from .exceptions import BadRequest
from .mapping import load_mapping
from .mount_link import LinkConfig, MountLink
from .server import VssServer
from .telescope import Telescope, TelescopeConfig

__all__ = ["build_server"]


def build_server(*, mount_url: str, password: str | None = None,
                 mapping_path: str | Path | None = None, site: Site | None = None,
                 speed: float = 1.0, simulated: bool | None = None, active: bool = True,
                 pointing_model: str | Path | None = None, heartbeat_s: float = 1.0,
                 clock: MountClock | None = None,
                 connector: Callable[[], Awaitable[Any]] | None = None,
                 access: AccessConfig | None = None, signals_url: str | None = None,
                 camera: CameraLinkConfig | None = None,
                 **telescope_options) -> VssServer:
    """Return a VssServer for the mount at `mount_url` (not started yet).

    mount_url: an ASTCom URL (ws://, tcp://...), or alpaca://HOST:PORT/N or
    indi://HOST:PORT/DEVICE for a driver's mount (`backends`).

    speed: mount seconds per wall second of a mount that runs by itself (> 1 for a
    free-running simulated emulator); simulated defaults to speed != 1.
    clock: a `virtualstar.lockstep.LockstepClock` shared with an embedded emulator
    (lockstep simulated time: `speed` is ignored, the clock has its pace), with
    `connector` opening the in-memory connection to it. The time mode and the margins
    follow from the clock (`clock.Margins`). mount_endpoint (a telescope option): the
    ASTCom URL clients are told the mount answers at (default `mount_url` when it is
    one). access: the API's passwords and allowed origins (default: none, loopback pages
    only). signals_url: where an Alpaca or INDI mount's reports are served as ASTCom
    signals for the recorder (`backend_signals`). camera: a guide camera device for
    closed-loop tracking (camera_link.py). Raises MappingError, BadRequest.
    """
    the_site = site or load_site()
    if is_rate_mount_url(mount_url):
        # an Alpaca or INDI driver: real time on the host clock, the VSS closing the loop
        if mapping_path is not None or speed != 1.0 or clock is not None:
            raise BadRequest(f"{mount_url}: --mapping and --speed apply to ASTCom mounts only "
                             "(an Alpaca or INDI driver runs in real time)")
        link = open_rate_mount(mount_url, the_site)
    else:
        link = MountLink(LinkConfig(mount_url, password, connector=connector),
                         load_mapping(mapping_path))
    clock = clock or PacedClock(speed)
    if simulated is None:
        simulated = clock.lockstep or clock.speed != 1.0
    if "://" in mount_url and not is_rate_mount_url(mount_url):  # an ASTCom endpoint
        telescope_options.setdefault("mount_endpoint", mount_url)
    config = TelescopeConfig(site=the_site, simulated=simulated, active=active,
                             **telescope_options)
    telescope = Telescope(link, config, clock)
    telescope.signals_url = signals_url
    if camera is not None:
        telescope.steering.camera = CameraLink(camera)
    if pointing_model is not None:
        telescope.load_model(str(pointing_model))
    return VssServer(telescope, heartbeat_s=heartbeat_s, access=access)
