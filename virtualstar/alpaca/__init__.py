"""ASCOM Alpaca façade: observers' software (NINA, Voyager, SkySafari, scripts) drives the VSS.

`protocol` holds the Alpaca rules without I/O (parameters, transaction ids, error
numbers, the JSON envelope); `telescope` maps every ITelescopeV4 member onto VSS
commands; `server` is the thin aiohttp transport and `discovery` the UDP responder.
Nothing here talks to the mount: every motion goes through the VSS supervisor, so
the Sun zone, the horizon and the one-owner rule hold for Alpaca clients too.
"""

from .server import AlpacaService, serve_alpaca
from .telescope import AlpacaTelescope, TelescopeOptions

__all__ = ["AlpacaService", "AlpacaTelescope", "TelescopeOptions", "serve_alpaca"]
