"""The Alpaca HTTP transport (aiohttp) and the service that runs it beside UDP discovery.

Routes: the management API (`/management/apiversions`, `/management/v1/description`,
`/management/v1/configureddevices`), the device API `/api/v1/telescope/0/<member>`
(GET and PUT) and a setup page. Everything Alpaca-specific is in `protocol` and
`telescope`; here only HTTP: status codes, bodies, and who may send.

Who may send: Alpaca has no passwords, so the façade listens on loopback unless told
otherwise (`trust_network`, explicit and logged), and refuses any request a browser
sends from a foreign page (an `Origin` not on the allow-list): a web page must not
be able to slew the telescope through the observer's own browser.
"""

from __future__ import annotations

import logging
import uuid
from dataclasses import dataclass, field
from typing import Any

from aiohttp import web
from aiohttp.http_exceptions import HttpProcessingError
from aiohttp.web_protocol import RequestPayloadError

from astcom_client.origins import check_allowed_origins, is_loopback_host, origin_refusal

from .discovery import DiscoveryResponder, start_discovery
from .protocol import (
    MAX_FORM_FIELDS,
    AlpacaError,
    BadParameter,
    Params,
    TransactionCounter,
    form_pairs,
    reply,
)
from .telescope import AlpacaTelescope, TelescopeOptions

__all__ = ["AlpacaService", "build_app", "serve_alpaca"]

log = logging.getLogger("virtualstar.alpaca")

DEFAULT_PORT = 11111
DEVICE_TYPE = "telescope"
DEVICE_NUMBER = 0
UNIQUE_ID = str(uuid.uuid5(uuid.NAMESPACE_URL, "virtualstar:alpaca:telescope:0"))


def build_app(device: AlpacaTelescope, *, allowed_origins: tuple[str, ...] | None = None,
              location: str = "") -> web.Application:
    """The aiohttp application of one telescope device."""
    counter = TransactionCounter()

    def ids(request: web.Request, params: Params) -> tuple[int, int]:
        _client, client_tid = params.transaction_ids()
        return client_tid, counter.next()

    async def params_of(request: web.Request) -> Params:
        if request.method == "PUT":
            return Params.from_pairs(await _put_pairs(request), exact=True)
        return Params.from_pairs(request.query.items())

    @web.middleware
    async def guard(request: web.Request, handler):
        origin = request.headers.get("Origin")
        if origin is not None:
            why = origin_refusal([origin], allowed_origins)
            if why is not None:
                log.warning("refused %s %s from Origin %r", request.method, request.path, origin)
                return web.Response(status=403, text=f"Origin {origin[:100]!r} refused: the "
                                    "Alpaca façade answers pages served from loopback only, "
                                    "unless started with --allow-origin ORIGIN")
        try:
            return await handler(request)
        except BadParameter as exc:
            return web.Response(status=400, text=str(exc))

    async def management(request: web.Request, value: Any) -> web.Response:
        params = await params_of(request)
        client_tid, server_tid = ids(request, params)
        return web.json_response(reply(client_tid, server_tid, value=value, has_value=True))

    async def api_versions(request: web.Request) -> web.Response:
        return await management(request, [1])

    async def description(request: web.Request) -> web.Response:
        return await management(request, {"ServerName": "VirtualStar Alpaca",
                                          "Manufacturer": "VirtualStar",
                                          "ManufacturerVersion": "1.0",
                                          "Location": location})

    async def configured(request: web.Request) -> web.Response:
        return await management(request, [{"DeviceName": device.options.name,
                                           "DeviceType": "Telescope",
                                           "DeviceNumber": DEVICE_NUMBER, "UniqueID": UNIQUE_ID}])

    async def api(request: web.Request) -> web.Response:
        kind = request.match_info["device_type"]
        number = request.match_info["number"]
        name = request.match_info["member"]
        if kind != DEVICE_TYPE or number != str(DEVICE_NUMBER):
            return web.Response(status=404, text=f"no device {kind}/{number}: this server has "
                                f"{DEVICE_TYPE}/{DEVICE_NUMBER} only")
        if not device.knows(name):
            return web.Response(status=404, text=f"{kind}/{number} has no member {name!r} "
                                "(member names are lower case)")
        if not device.takes(request.method, name):
            return web.Response(status=405, text=f"{name} does not take {request.method}")
        params = await params_of(request)
        client_tid, server_tid = ids(request, params)
        try:
            value = await device.handle(request.method, name, params)
        except AlpacaError as exc:
            log.info("%s %s: ASCOM error 0x%X %s", request.method, name, exc.number, exc.message)
            return web.json_response(reply(client_tid, server_tid, error=exc))
        return web.json_response(reply(client_tid, server_tid, value=value,
                                       has_value=request.method == "GET" or value is not None))

    async def setup(request: web.Request) -> web.Response:
        return web.Response(content_type="text/html", text=(
            "<html><body><h1>VirtualStar telescope</h1><p>Configured on the VirtualStar Server "
            "(site, horizon, Sun zone, passwords): see <code>vs alpaca --help</code>.</p>"
            "</body></html>"))

    app = web.Application(middlewares=[guard])
    app.router.add_get("/management/apiversions", api_versions)
    app.router.add_get("/management/v1/description", description)
    app.router.add_get("/management/v1/configureddevices", configured)
    app.router.add_route("*", "/api/v1/{device_type}/{number}/{member}", api)
    app.router.add_get("/setup", setup)
    app.router.add_get("/setup/v1/{device_type}/{number}/setup", setup)
    return app


#: What a PUT without a Content-Type header is read as (aiohttp says octet-stream).
_FORM_TYPES = ("application/x-www-form-urlencoded", "application/octet-stream", "text/plain")


# What reading a body raises when its bytes are not what its headers say (a Content-Encoding
# that does not decode, a chunk that lies): the client's fault, so HTTP 400, never 500.
_PAYLOAD_ERRORS = (RequestPayloadError, HttpProcessingError)


async def _put_pairs(request: web.Request) -> list[tuple[str, str]]:
    """Return a PUT's form fields; BadParameter (HTTP 400) for a body that is not a form."""
    kind = request.content_type
    if kind in _FORM_TYPES:
        try:
            body = await request.read()  # read() keeps to the size cap (413 beyond it)
        except _PAYLOAD_ERRORS as exc:
            raise BadParameter(f"the body cannot be read as sent: {_payload_reason(exc)}") \
                from None
        return form_pairs(body, request.charset)
    if kind != "multipart/form-data":
        raise BadParameter(f"a PUT's parameters are a form (application/x-www-form-urlencoded "
                           f"or multipart/form-data), not {kind[:80]}")
    try:
        form = await request.post()
    except _PAYLOAD_ERRORS as exc:
        raise BadParameter(f"the multipart body cannot be read as sent: "
                           f"{_payload_reason(exc)}") from None
    except (ValueError, LookupError, AssertionError) as exc:  # UnicodeDecodeError included
        raise BadParameter(f"the multipart body cannot be read: {str(exc)[:200]}") from None
    if len(form) > MAX_FORM_FIELDS:
        raise BadParameter(f"the form body has more than {MAX_FORM_FIELDS} fields")
    pairs = []
    for name, value in form.items():
        if not isinstance(value, str):
            raise BadParameter(f"the multipart part {name[:80]!r} is a file upload; Alpaca "
                               "parameters are plain form fields")
        pairs.append((name, value))
    return pairs


def _payload_reason(exc: Exception) -> str:
    cause = exc.__cause__ or exc
    text = getattr(cause, "message", None) or str(cause)
    return f"{text}"[:200] or type(cause).__name__


@dataclass
class AlpacaService:
    """A running façade: its HTTP URL, the discovery responder, and how to stop both."""

    url: str
    port: int
    device: AlpacaTelescope
    runner: web.AppRunner
    discovery: DiscoveryResponder | None = None
    notes: list[str] = field(default_factory=list)

    async def close(self) -> None:
        if self.discovery is not None:
            self.discovery.close()
        await self.device.close()
        await self.runner.cleanup()


async def serve_alpaca(vss, *, host: str = "127.0.0.1", port: int = DEFAULT_PORT,
                       discovery_bind: str | None = "127.0.0.1", discovery_port: int = 32227,
                       options: TelescopeOptions | None = None,
                       allowed_origins: list[str] | None = None,
                       trust_network: bool = False, location: str = "") -> AlpacaService:
    """Serve the Alpaca telescope for a VSS client (`VssClient` or the in-process one).

    Raises ValueError for a non-loopback `host` without `trust_network`.
    """
    if not is_loopback_host(host) and not trust_network:
        raise ValueError(f"listening on {host} would let anyone on that network move the "
                         "telescope (Alpaca has no passwords): listen on 127.0.0.1, or give "
                         "--trust-network to accept it on a network you control")
    if trust_network and not is_loopback_host(host):
        log.warning("Alpaca façade listening on %s: every client on that network may move the "
                    "telescope", host)
    device = AlpacaTelescope(vss, options)
    app = build_app(device, allowed_origins=check_allowed_origins(allowed_origins),
                    location=location)
    runner = web.AppRunner(app, access_log=None)
    await runner.setup()
    site = web.TCPSite(runner, host, port)
    await site.start()
    bound = site._server.sockets[0].getsockname()[1]  # type: ignore[union-attr]
    service = AlpacaService(f"http://{host}:{bound}", bound, device, runner)
    if discovery_bind is not None:
        try:
            service.discovery = await start_discovery(discovery_bind, discovery_port, bound)
        except OSError as exc:
            await service.close()
            raise OSError(f"Alpaca discovery cannot listen on UDP {discovery_bind}:"
                          f"{discovery_port}: {exc}; give --discovery-port or "
                          "--no-discovery") from None
    return service
