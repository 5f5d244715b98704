"""Put a VSS together from plain options (the one place defaults meet)."""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

from virtualstar.astro import Site, load_site

from .access import AccessConfig
from .camera_link import CameraLink, CameraLinkConfig
from .clock import MountClock, PacedClock
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
                 access: AccessConfig | None = None,
                 camera: CameraLinkConfig | None = None,
                 **telescope_options) -> VssServer:
    """Return a VssServer for the mount at `mount_url` (not started yet).

    speed: mount seconds per wall second of a mount that runs by itself (> 1 for a
    free-running simulated emulator); simulated defaults to speed != 1.
    clock: a `virtualstar.lockstep.LockstepClock` shared with an embedded emulator
    (lockstep simulated time: `speed` is ignored, the clock has its pace), with
    `connector` opening the in-memory connection to it. The time mode and the margins
    follow from the clock (`clock.Margins`). mount_endpoint (a telescope option): the
    ASTCom URL clients are told the mount answers at (default `mount_url` when it is
    one). access: the API's passwords and allowed
    origins (default: none, loopback pages only). camera: a guide camera device for
    closed-loop tracking (camera_link.py). Raises MappingError, BadRequest.
    """
    mapping = load_mapping(mapping_path)
    link = MountLink(LinkConfig(mount_url, password, connector=connector), mapping)
    clock = clock or PacedClock(speed)
    if simulated is None:
        simulated = clock.lockstep or clock.speed != 1.0
    if "://" in mount_url:
        telescope_options.setdefault("mount_endpoint", mount_url)
    config = TelescopeConfig(site=site or load_site(), simulated=simulated, active=active,
                             **telescope_options)
    telescope = Telescope(link, config, clock)
    if camera is not None:
        telescope.steering.camera = CameraLink(camera)
    if pointing_model is not None:
        telescope.load_model(str(pointing_model))
    return VssServer(telescope, heartbeat_s=heartbeat_s, access=access)
