"""`vs server`: run the VirtualStar Server against a mount, or an embedded emulator."""

from __future__ import annotations

import asyncio
import logging
import signal
from pathlib import Path
from typing import Annotated

import typer

from virtualstar.astro import AstroError
from virtualstar.astro.site import site_from_options
from virtualstar.cli.status import fail
from virtualstar.server import DEFAULT_PORT, VssError, build_server

__all__ = ["server"]


def server(
    emulator: Annotated[bool, typer.Option(
        "--emulator", help="Start the bundled mount emulator in this process and drive it.")] = False,
    speed: Annotated[float, typer.Option(
        "--speed", help="With --emulator: simulated time at X times real time (1 = real time).")] = 1.0,
    start: Annotated[str | None, typer.Option(
        "--start", help="With --emulator: mount time at start, ISO-8601 UTC (default now).")] = None,
    geometry: Annotated[Path | None, typer.Option(
        "--geometry", help="With --emulator: hidden pointing errors (TPOINT terms, arcsec) from a "
        "TOML or JSON file, as for mount-emulator; default a perfect mount.")] = None,
    seed: Annotated[int | None, typer.Option(
        "--seed", help="With --emulator: draw hidden pointing errors (>= 100 arcsec RMS) from this "
        "seed, as `mount-emulator --seed N` does.")] = None,
    mount: Annotated[str | None, typer.Option(
        "--mount", help="ASTCom URL of the mount, e.g. ws://mount:8765 (instead of --emulator).")] = None,
    password: Annotated[str | None, typer.Option(
        "--password", envvar="ASTCOM_PASSWORD", help="Operator password of the mount.")] = None,
    mapping: Annotated[Path | None, typer.Option(
        "--mapping", help="JSON role mapping for the mount (default: the emulator's).")] = None,
    listen: Annotated[str, typer.Option(
        "--listen", help="Where clients connect: ws://HOST:PORT.")] = f"ws://127.0.0.1:{DEFAULT_PORT}",
    site_file: Annotated[Path | None, typer.Option(
        "--site-file", envvar="VIRTUALSTAR_SITE", help="Site TOML file with a [site] table.")] = None,
    site: Annotated[str | None, typer.Option(
        "--site", help="Site as LAT,LON,HEIGHT_M (degrees, degrees east, metres).")] = None,
    pointing_model: Annotated[Path | None, typer.Option(
        "--pointing-model", help="Pointing model JSON file to apply (observed → encoder).")] = None,
    passive: Annotated[bool, typer.Option(
        "--passive", help="Only watch the mount; refuse commands that move it.")] = False,
    verbose: Annotated[bool, typer.Option("--verbose", "-v", help="Log connection events.")] = False,
) -> None:
    """Serve clients (vs status/slew/track/...) until Ctrl-C; the mount is fed continuously."""
    logging.basicConfig(level=logging.INFO if verbose else logging.WARNING,
                        format="%(asctime)s %(name)s: %(message)s")
    if emulator == (mount is not None):
        raise fail("give either --emulator or --mount URL")
    if not (speed > 0 and speed < 1000):
        raise fail(f"--speed {speed}: expected a number of times real time, > 0 and < 1000")
    if not emulator and (speed != 1.0 or start is not None):
        raise fail("--speed and --start only apply to --emulator (a real mount runs in real time)")
    geometry_arcsec = None
    if geometry is not None or seed is not None:
        if not emulator:
            raise fail("--geometry and --seed only apply to --emulator (a real mount has its own)")
        from virtualstar.launcher import hidden_geometry_arcsec

        try:
            geometry_arcsec = hidden_geometry_arcsec(path=geometry, seed=seed)
        except ValueError as exc:
            raise fail(f"--geometry/--seed: {exc}") from None
    start_us = None
    if start is not None:
        from virtualstar.astro import UtcTimes

        try:
            start_us = int(UtcTimes.from_iso([start]).to_unix_us()[0])
        except AstroError as exc:
            raise fail(f"--start: {exc}") from None
    try:
        the_site = site_from_options(site_file=site_file, site_text=site)
    except AstroError as exc:
        raise fail(str(exc)) from None
    _warn_once_about_earth_orientation(start_us)
    try:
        asyncio.run(_serve(emulator, speed, start_us, mount, password, mapping, listen, the_site,
                           pointing_model, passive, geometry_arcsec))
    except VssError as exc:
        raise fail(str(exc)) from None
    except OSError as exc:
        raise fail(f"cannot listen on {listen}: {exc.strerror or exc}", 1) from None


def _warn_once_about_earth_orientation(start_us: int | None) -> None:
    """Say once (not at every trajectory chunk) when UT1/polar motion are predictions."""
    import time
    import warnings

    from virtualstar.astro import EarthOrientation, EarthOrientationWarning

    warnings.filterwarnings("ignore", category=EarthOrientationWarning)
    mjd = (start_us if start_us is not None else time.time_ns() // 1000) / 86_400e6 + 40587.0
    eop = EarthOrientation.from_astropy_iers_data()
    if mjd > eop.measured_until_mjd:
        typer.echo(f"warning: the mount time lies {mjd - eop.measured_until_mjd:.0f} days after "
                   "the last measured IERS value: predicted UT1-UTC and polar motion are used "
                   "(update astropy-iers-data for arcsecond-accurate satellites)", err=True)


async def _serve(emulator, speed, start_us, mount, password, mapping, listen, site,
                 pointing_model, passive, geometry_arcsec=None) -> None:
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    embedded = None
    if emulator:
        from virtualstar.launcher import start_emulator

        embedded = await start_emulator(speed=speed, start_us=start_us, password=password,
                                         geometry_arcsec=geometry_arcsec)
        mount = embedded.url
    vss = build_server(mount_url=mount, password=password, mapping_path=mapping, site=site,
                       speed=speed, active=not passive, pointing_model=pointing_model)
    try:
        url = await vss.start(listen)
        where = f"embedded emulator {mount}" + (f", x{speed:g} simulated time" if speed != 1 else "")
        typer.echo(f"VirtualStar Server on {url} (mount: {where if emulator else mount})")
        await stop.wait()
    finally:
        await vss.close()
        if embedded is not None:
            await embedded.stop()
        typer.echo("VirtualStar Server stopped")
