"""Mount backends behind the VSS's mount link, chosen by the mount URL's scheme.

* ``ws://``, ``wss://``, ``tcp://``, ``tls://``: an ASTCom controller (`mount_link.MountLink`,
  trajectory buffer; the emulator or a controller running the C device library).
* ``alpaca://HOST:PORT/N``: ASCOM Alpaca telescope number N (`alpaca.AlpacaDriver`).
* ``indi://HOST:PORT/DEVICE``: an INDI telescope driver under indiserver (`indi.IndiDriver`).

The last two are rate-driven mounts (`rate_mount.RateMountLink`): gotos and axis
rates, the VSS closing the loop on the reported position (`server/rate_loop.py`).
"""

from __future__ import annotations

from urllib.parse import urlsplit

from virtualstar.astro import EarthOrientation, Site

from ..exceptions import BadRequest
from .rate_mount import RateLinkConfig, RateMountLink

__all__ = ["RATE_SCHEMES", "is_rate_mount_url", "open_rate_mount"]

RATE_SCHEMES = ("alpaca", "indi")


def is_rate_mount_url(url: str) -> bool:
    """True for a mount URL that names an Alpaca or INDI driver (not an ASTCom controller)."""
    return urlsplit(url).scheme in RATE_SCHEMES


def open_rate_mount(url: str, site: Site, eop: EarthOrientation | None = None,
                    **options) -> RateMountLink:
    """Return the (not yet started) link to the Alpaca or INDI mount at `url`; BadRequest."""
    scheme = urlsplit(url).scheme
    eop = eop or EarthOrientation.from_astropy_iers_data()
    config = RateLinkConfig(url, site, eop, **options)
    if scheme == "alpaca":
        from .alpaca import AlpacaDriver

        return RateMountLink(AlpacaDriver(url, timeout_s=config.timeout_s), config,
                             backend="alpaca")
    if scheme == "indi":
        from .indi import IndiDriver

        return RateMountLink(IndiDriver(url, timeout_s=config.timeout_s), config, backend="indi")
    raise BadRequest(f"mount URL {url!r}: expected alpaca://HOST:PORT/N, indi://HOST:PORT/DEVICE "
                     "or an ASTCom URL (ws://, wss://, tcp://, tls://)")
