"""`vs alpaca`: serve the telescope to ASCOM Alpaca clients (NINA, Voyager, SkySafari, scripts)."""

from __future__ import annotations

import asyncio
import logging
from typing import Annotated

import typer

from virtualstar.cli.server import _stop_event
from virtualstar.cli.status import ServerOpt, api_password, fail

__all__ = ["alpaca"]


def alpaca(
    server: ServerOpt = None,
    emulator: Annotated[bool, typer.Option(
        "--emulator", help="Run the bundled mount emulator and a VirtualStar Server in this "
        "process (real time) and serve them, instead of connecting to --server.")] = False,
    listen: Annotated[str, typer.Option(
        "--listen", help="HOST:PORT of the Alpaca HTTP API (Alpaca's usual port is 11111).")
    ] = "127.0.0.1:11111",
    discovery_bind: Annotated[str, typer.Option(
        "--discovery-bind", help="Address the UDP discovery responder binds (port "
        "--discovery-port): 127.0.0.1 answers this host only; 0.0.0.0 answers the network's "
        "broadcasts (needs --trust-network).")] = "127.0.0.1",
    discovery_port: Annotated[int, typer.Option(
        "--discovery-port", help="UDP port of Alpaca discovery (32227 is the standard).")] = 32227,
    no_discovery: Annotated[bool, typer.Option(
        "--no-discovery", help="Do not answer discovery requests.")] = False,
    trust_network: Annotated[bool, typer.Option(
        "--trust-network", help="Allow --listen / --discovery-bind beyond loopback. Alpaca has "
        "no passwords: every client on that network may then move the telescope.")] = False,
    allow_origin: Annotated[list[str] | None, typer.Option(
        "--allow-origin", help="A web page origin allowed to send requests (repeatable; default: "
        "pages served from loopback only).")] = None,
    aperture_m: Annotated[float | None, typer.Option(
        "--aperture-diameter-m", help="Aperture diameter in metres (ApertureDiameter; area "
        "from it unless --aperture-area-m2).")] = None,
    aperture_area_m2: Annotated[float | None, typer.Option(
        "--aperture-area-m2", help="Clear aperture area in square metres (ApertureArea).")] = None,
    focal_length_m: Annotated[float | None, typer.Option(
        "--focal-length-m", help="Focal length in metres (FocalLength).")] = None,
    verbose: Annotated[bool, typer.Option("--verbose", "-v", help="Log every refusal.")] = False,
) -> None:
    """Serve an ASCOM Alpaca Telescope (ITelescopeV4) that drives the VirtualStar Server; Ctrl-C stops.

    Every motion goes through the server: the Sun zone, the horizon and its access
    rules apply (this façade is one of its operator clients: give the operator
    password with vs --password). Point NINA, Voyager or any Alpaca client at the
    printed address (docs/alpaca-indi.md).
    """
    import math

    logging.basicConfig(level=logging.INFO if verbose else logging.WARNING,
                        format="%(asctime)s %(name)s: %(message)s")
    host, _, port_text = listen.rpartition(":")
    if not host or not port_text.isdigit() or not 0 <= int(port_text) < 65536:
        raise fail(f"--listen {listen!r}: expected HOST:PORT, e.g. 127.0.0.1:11111")
    from astcom_client.origins import is_loopback_host

    if not trust_network and not is_loopback_host(host):
        raise fail(f"--listen {listen}: beyond loopback anyone on that network could move the "
                   "telescope (Alpaca has no passwords); add --trust-network to mean it")
    if emulator and server is not None:
        raise fail("give either --emulator or --server URL, not both")
    if not 0 <= discovery_port < 65536:
        raise fail(f"--discovery-port {discovery_port}: expected 0..65535")
    for name, value in (("--aperture-diameter-m", aperture_m),
                        ("--aperture-area-m2", aperture_area_m2),
                        ("--focal-length-m", focal_length_m)):
        if value is not None and not (math.isfinite(value) and value > 0):
            raise fail(f"{name} {value:g}: expected a positive number")
    if aperture_area_m2 is None and aperture_m is not None:
        aperture_area_m2 = math.pi * aperture_m**2 / 4
    from virtualstar.alpaca import TelescopeOptions

    options = TelescopeOptions(aperture_diameter_m=aperture_m, aperture_area_m2=aperture_area_m2,
                               focal_length_m=focal_length_m)
    bind = None if no_discovery else discovery_bind
    if bind is not None and not trust_network and not is_loopback_host(bind):
        raise fail(f"--discovery-bind {bind}: answering discovery beyond loopback tells the "
                   "network where to move the telescope; add --trust-network to mean it")
    run = _run(server, emulator, host, int(port_text), bind, discovery_port, options,
               allow_origin, trust_network)
    try:
        asyncio.run(run)
    except ValueError as exc:
        raise fail(str(exc)) from None
    except OSError as exc:
        raise fail(f"cannot serve Alpaca on {listen}: {exc.strerror or exc}", 1) from None


async def _run(server_url, emulator, host, port, bind, discovery_port, options, origins,
               trust) -> None:
    from virtualstar.alpaca import serve_alpaca
    from virtualstar.vss_client import (
        ServerUnavailable,
        VssClient,
        VssRequestError,
        default_server_url,
    )

    stop = _stop_event()

    async def serve(vss, what: str) -> None:
        service = await serve_alpaca(vss, host=host, port=port, discovery_bind=bind,
                                     discovery_port=discovery_port, options=options,
                                     allowed_origins=origins, trust_network=trust)
        disc = (f"; discovery on UDP {bind}:{service.discovery.port}"
                if service.discovery is not None else "")
        typer.echo(f"Alpaca telescope 0 at {service.url} (driving {what}){disc}; Ctrl-C stops",
                   err=True)
        try:
            await stop.wait()
        finally:
            await service.close()

    if emulator:
        from virtualstar.launcher import embedded_vss

        async with embedded_vss() as vss:
            await serve(vss.client(), "the embedded emulator")
        return
    url = server_url or default_server_url()
    try:
        client = await VssClient.connect(url, reconnect=True, password=api_password())
    except (ServerUnavailable, VssRequestError) as exc:
        raise fail(str(exc), 2 if isinstance(exc, ServerUnavailable) else 1) from None
    if client.role != "operator":
        await client.close()
        raise fail(f"the VirtualStar Server at {url} gave this connection the {client.role} "
                   "role: an Alpaca client moves the telescope, so give the operator password "
                   "(vs --password PW alpaca)", 1)
    async with client:
        await serve(client, url)
