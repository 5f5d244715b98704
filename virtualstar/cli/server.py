"""`vs server`: run the VirtualStar Server against a mount, or an embedded emulator."""

from __future__ import annotations

import asyncio
import logging
import math
import signal
import time
from pathlib import Path
from typing import Annotated

import typer

from virtualstar.cli.status import fail
from virtualstar.launcher import DEFAULT_ENDPOINT_PORT, EndpointUnavailable
from virtualstar.vss_client import DEFAULT_SERVER_URL

# The server, the astronomy and the emulator are imported when the command runs: --help
# stays fast (benchmarks/bench_cli_startup.py; tests/test_import_rules.py). The launcher
# imports the emulator only when it starts one.

__all__ = ["server"]


def server(
    emulator: Annotated[bool, typer.Option(
        "--emulator", help="Start the bundled mount emulator in this process and drive it.")] = False,
    speed: Annotated[str, typer.Option(
        "--speed", help="With --emulator: 1 = real time on the host clock (default); 'max' = "
        "lockstep simulated time, as fast as the CPU allows (the server and the emulator share "
        "one clock, so the server is never late); X = lockstep at up to X times real time. "
        "With --mount: the mount is a simulated emulator running by itself at X times real "
        "time (margins grow with X).")] = "1",
    start: Annotated[str | None, typer.Option(
        "--start", help="With --emulator: mount time at start, ISO-8601 UTC (default now).")] = None,
    geometry: Annotated[Path | None, typer.Option(
        "--geometry", help="With --emulator: hidden pointing errors (TPOINT terms, arcsec) from a "
        "TOML or JSON file, as for mount-emulator; default a perfect mount.")] = None,
    seed: Annotated[int | None, typer.Option(
        "--seed", help="With --emulator: draw hidden pointing errors (>= 100 arcsec RMS) from this "
        "seed, as `mount-emulator --seed N` does.")] = None,
    endpoint_port: Annotated[int | None, typer.Option(
        "--endpoint-port", show_default=False,
        help=f"With --emulator: the loopback port of the emulator's ASTCom endpoint for other "
        f"clients (the panel, astcom, the recorder), default {DEFAULT_ENDPOINT_PORT}; fixed, so "
        "a restarted server is found where it was. 0 picks a free port. Clients are told where "
        "it is (status: mount_endpoint).")] = None,
    mount: Annotated[str | None, typer.Option(
        "--mount", help="The mount, instead of --emulator: an ASTCom URL (ws://mount:8765), an "
        "ASCOM Alpaca telescope alpaca://HOST:PORT/N, or an INDI telescope "
        "indi://HOST:PORT/DEVICE (see docs/mount-backends.md).")] = None,
    password: Annotated[str | None, typer.Option(
        "--password", envvar="ASTCOM_PASSWORD", help="Operator password of the mount's ASTCom "
        "endpoint (the server's own API passwords: --operator-password, --observer-password). "
        "With --emulator and API passwords, the embedded emulator's endpoint takes the API's "
        "operator and observer passwords unless this is given.")] = None,
    mapping: Annotated[Path | None, typer.Option(
        "--mapping", help="JSON role mapping for the mount (default: the emulator's).")] = None,
    operator_password: Annotated[str | None, typer.Option(
        "--operator-password", envvar="VS_OPERATOR_PASSWORD", show_default=False,
        help="Password of the operator role of this server's API (moves and configures); "
        "clients give it with vs --password. Required to listen beyond loopback.")] = None,
    observer_password: Annotated[str | None, typer.Option(
        "--observer-password", envvar="VS_OBSERVER_PASSWORD", show_default=False,
        help="Password of the observer role (status, watch, errors only).")] = None,
    allow_origin: Annotated[list[str] | None, typer.Option(
        "--allow-origin", help="A web page origin allowed to connect, e.g. http://panel:8080 "
        "(repeat for more; default: pages served from loopback only).")] = None,
    listen: Annotated[str, typer.Option(
        "--listen", help="Where clients connect: ws://HOST:PORT.")] = DEFAULT_SERVER_URL,
    signals: Annotated[str | None, typer.Option(
        "--signals", help="With an alpaca:// or indi:// mount: serve its reports (place, rates, "
        "error) as ASTCom signals here, e.g. ws://127.0.0.1:8767, for `vs record`.")] = None,
    site_file: Annotated[Path | None, typer.Option(
        "--site-file", envvar="VIRTUALSTAR_SITE", help="Site TOML file with a \\[site] table (and optionally \\[safety]).")] = None,
    site: Annotated[str | None, typer.Option(
        "--site", help="Site as LAT,LON,HEIGHT_M (degrees, degrees east, metres).")] = None,
    sun_radius: Annotated[float | None, typer.Option(
        "--sun-radius", help="Radius (degrees) of the exclusion zone around the Sun: no target, "
        "slew path or track comes nearer (default 30, or sun_radius_deg in the site file's "
        "safety table).")] = None,
    moon_radius: Annotated[float | None, typer.Option(
        "--moon-radius", help="Radius (degrees) of an exclusion zone around the Moon (default "
        "none; 0 switches it off).")] = None,
    horizon: Annotated[Path | None, typer.Option(
        "--horizon", help="Horizon profile: a text file of 'AZ_DEG EL_DEG' lines, the lowest "
        "usable elevation per azimuth (docs/vss.md, 'Safety'); default the flat limit.")] = None,
    pointing_model: Annotated[Path | None, typer.Option(
        "--pointing-model", help="Pointing model JSON file to apply (observed → encoder).")] = None,
    passive: Annotated[bool, typer.Option(
        "--passive", help="Only watch the mount; refuse commands that move it.")] = False,
    camera: Annotated[str | None, typer.Option(
        "--camera", help="With --mount: ASTCom URL of a guide camera device (e.g. "
        "`guide-camera`'s) for closed-loop tracking (vs track --closed-loop).")] = None,
    camera_password: Annotated[str | None, typer.Option(
        "--camera-password", envvar="VS_CAMERA_PASSWORD", show_default=False,
        help="Password of the guide camera's endpoint.")] = None,
    camera_sim: Annotated[Path | None, typer.Option(
        "--camera-sim", help="With --emulator: run a simulated guide camera beside it, seeing "
        "the truth in this TOML file (docs/guide-camera.md), for closed-loop tracking.")] = None,
    camera_listen: Annotated[str, typer.Option(
        "--camera-listen", help="With --camera-sim: where the simulated camera's ASTCom "
        "endpoint listens for other clients (panel, recorder).")] = "ws://127.0.0.1:0",
    verbose: Annotated[bool, typer.Option("--verbose", "-v", help="Log connection events.")] = False,
) -> None:
    """Serve clients (vs status/slew/track/...) until Ctrl-C; the mount is fed continuously."""
    from virtualstar.astro import AstroError, avoidance_from_options
    from virtualstar.astro.site import site_from_options
    from virtualstar.server import AccessConfig, VssError
    from virtualstar.server.access import check_listen
    from virtualstar.server.server import parse_listen_url

    logging.basicConfig(level=logging.INFO if verbose else logging.WARNING,
                        format="%(asctime)s %(name)s: %(message)s")
    if emulator == (mount is not None):
        raise fail("give either --emulator or --mount URL")
    pace = parse_speed(speed)
    if not emulator and pace is None:
        raise fail("--speed max only applies to --emulator (lockstep needs the emulator in this "
                   "process); give --speed X for a simulated mount running at X times real time")
    if signals is not None and (emulator or mount is None or "://" not in mount
                                or mount.split("://")[0] not in ("alpaca", "indi")):
        raise fail("--signals applies to an alpaca:// or indi:// mount (an ASTCom mount "
                   "streams its own signals: record them from its endpoint)")
    if not emulator and start is not None:
        raise fail("--start only applies to --emulator (a mount keeps its own clock)")
    if endpoint_port is not None and not emulator:
        raise fail("--endpoint-port only applies to --emulator (--mount names the mount's endpoint)")
    if endpoint_port is None:
        endpoint_port = DEFAULT_ENDPOINT_PORT
    if not 0 <= endpoint_port <= 65535:
        raise fail(f"--endpoint-port {endpoint_port}: expected a TCP port, 0..65535 (0: a free one)")
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
    passwords = {role: pw for role, pw in (("operator", operator_password),
                                           ("observer", observer_password)) if pw}
    if passwords and "operator" not in passwords:
        raise fail("--observer-password needs --operator-password too (else nobody could "
                   "move the telescope)")
    try:
        access = AccessConfig(passwords=passwords or None, allowed_origins=allow_origin or None)
        # refused before anything starts (the embedded emulator's endpoint listens first)
        check_listen(parse_listen_url(listen)[0], access)
    except VssError as exc:
        raise fail(str(exc)) from None
    try:
        the_site = site_from_options(site_file=site_file, site_text=site)
        zones = avoidance_from_options(site_file=site_file, sun_radius_deg=sun_radius,
                                       moon_radius_deg=moon_radius, horizon_file=horizon)
    except AstroError as exc:
        raise fail(str(exc)) from None
    cameras = _camera_options(emulator, camera, camera_password, camera_sim, camera_listen,
                              the_site)
    _warn_once_about_earth_orientation(start_us)
    try:
        if emulator:
            clock = None  # real time: the emulator runs its own loop at ×1
            if pace != 1.0:
                from virtualstar.lockstep import LockstepClock

                # --speed max: as fast as the CPU allows while a client waits for an
                # operation, real time otherwise (docs/vss.md, "Time modes")
                clock = LockstepClock(start_us if start_us is not None
                                      else time.time_ns() // 1000, pace=pace,
                                      idle_pace=1.0 if pace is None else None)
            serve = _serve_embedded(clock, start_us, password, listen, the_site, mapping,
                                    pointing_model, passive, geometry_arcsec, zones, access,
                                    f"ws://127.0.0.1:{endpoint_port}", cameras)
            if clock is None:
                asyncio.run(serve)
            else:
                from virtualstar.lockstep import run_lockstep

                run_lockstep(serve, clock)
        else:
            asyncio.run(_serve(pace, mount, password, mapping, listen, the_site,
                               pointing_model, passive, zones, access, cameras, signals))
    except VssError as exc:
        raise fail(str(exc)) from None
    except EndpointUnavailable as exc:
        raise fail(f"{exc.strerror}; choose another with --endpoint-port PORT (0: a free one)",
                   1) from None
    except OSError as exc:
        raise fail(f"cannot listen on {listen}: {exc.strerror or exc}", 1) from None


def _camera_options(emulator: bool, url: str | None, password: str | None,
                    sim: Path | None, listen: str, site) -> dict:
    """The guide camera options: {} (none), {"camera": link} or {"camera": sim, "camera_url"}."""
    if sim is not None:
        if not emulator:
            raise fail("--camera-sim runs a simulated camera beside --emulator; with --mount, "
                       "run `guide-camera` beside the mount and give --camera URL")
        from virtualstar.launcher import camera_from_file

        try:
            return {"camera": camera_from_file(sim, site), "camera_url": listen}
        except ValueError as exc:
            raise fail(f"--camera-sim: {exc}") from None
    if url is not None:
        if emulator:
            raise fail("--camera URL goes with --mount; with --emulator use --camera-sim FILE")
        from virtualstar.server.camera_link import CameraLinkConfig

        return {"camera": CameraLinkConfig(url, password or None)}
    return {}


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


def parse_speed(text: str) -> float | None:
    """Return the --speed factor: None for 'max', else a number > 0 and < 1000."""
    if text.strip().lower() == "max":
        return None
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (0 < value < 1000):
        raise fail(f"--speed {text!r}: expected 'max' or a number of times real time, "
                   "> 0 and < 1000 (1 = real time)")
    return value


def _stop_event() -> asyncio.Event:
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    return stop


async def _serve_embedded(clock, start_us, password, listen, site, mapping,
                          pointing_model, passive, geometry_arcsec, zones, access,
                          emulator_url, cameras) -> None:
    from virtualstar.launcher import embedded_vss

    # The emulator's own ASTCom endpoint inherits the server's protection: with API
    # passwords it takes the same ones (--password, if given, for the operator instead),
    # else anyone who can reach its port could stop the operator's track.
    guard, observer_password = "", None
    if access.passwords:
        observer_password = access.passwords.get("observer")
        if password is None:
            password = access.passwords["operator"]
            guard = "the server's operator password" + (
                " and its observer password" if observer_password else "")
        else:
            guard = "--password as its operator password"
    stop = _stop_event()
    async with embedded_vss(clock=clock, speed=1.0, start_us=start_us, site=site,
                            listen=listen, password=password,
                            observer_password=observer_password, emulator_url=emulator_url,
                            geometry_arcsec=geometry_arcsec,
                            mapping_path=mapping, active=not passive,
                            pointing_model=pointing_model, zones=zones, access=access,
                            **cameras) as vss:
        if clock is None:
            mode = "real time"
        elif clock.busy_pace is None:
            mode = ("lockstep simulated time, as fast as the CPU allows while a client waits "
                    "for an operation, real time otherwise")
        else:
            mode = f"lockstep simulated time, up to x{clock.pace:g}"
        typer.echo(f"VirtualStar Server on {vss.url} (mount: embedded emulator, {mode}; its "
                   f"ASTCom endpoint for other clients: {vss.emulator.url})")
        if vss.camera is not None:
            typer.echo(f"simulated guide camera on {vss.camera.url}"
                       + (" (the same passwords)" if guard else ""))
        if guard:
            typer.echo(f"The emulator's ASTCom endpoint takes {guard}.")
        await stop.wait()
    typer.echo("VirtualStar Server stopped")


async def _serve(speed, mount, password, mapping, listen, site, pointing_model, passive,
                 zones, access, cameras, signals=None) -> None:
    from virtualstar.server import build_server

    stop = _stop_event()
    vss = build_server(mount_url=mount, password=password, mapping_path=mapping, site=site,
                       speed=speed, active=not passive, pointing_model=pointing_model,
                       zones=zones, access=access, signals_url=signals, **cameras)
    try:
        url = await vss.start(listen)
        where = mount + (f", a simulated mount at x{speed:g}" if speed != 1 else "")
        typer.echo(f"VirtualStar Server on {url} (mount: {where})")
        if vss.telescope.signals is not None:
            typer.echo(f"the mount's reports as ASTCom signals on {vss.telescope.signals.url}")
        await stop.wait()
    finally:
        await vss.close()
        typer.echo("VirtualStar Server stopped")
