"""Put a VSS together from plain options (the one place defaults meet)."""

from __future__ import annotations

from pathlib import Path

from virtualstar.astro import Site, load_site

from .mapping import load_mapping
from .mount_link import LinkConfig, MountLink
from .server import VssServer
from .telescope import Telescope, TelescopeConfig

__all__ = ["build_server"]


def build_server(*, mount_url: str, password: str | None = None,
                 mapping_path: str | Path | None = None, site: Site | None = None,
                 speed: float = 1.0, simulated: bool | None = None, active: bool = True,
                 pointing_model: str | Path | None = None, heartbeat_s: float = 1.0,
                 **telescope_options) -> VssServer:
    """Return a VssServer for the mount at `mount_url` (not started yet).

    speed: mount seconds per wall second (> 1 for a simulated-time emulator);
    simulated defaults to speed != 1. Raises MappingError, BadRequest (model file).
    """
    mapping = load_mapping(mapping_path)
    link = MountLink(LinkConfig(mount_url, password), mapping)
    config = TelescopeConfig(site=site or load_site(), speed=speed,
                             simulated=(speed != 1.0) if simulated is None else simulated,
                             active=active, **telescope_options)
    telescope = Telescope(link, config)
    if pointing_model is not None:
        telescope.load_model(str(pointing_model))
    return VssServer(telescope, heartbeat_s=heartbeat_s)
