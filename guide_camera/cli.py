"""`guide-camera`: a simulated guide camera beside a running mount emulator, over ASTCom.

    guide-camera truth.toml --mount ws://127.0.0.1:8765 --site-file site.toml
    vs server --mount ws://127.0.0.1:8765 --camera ws://127.0.0.1:8777
    vs track --tle stations.tle --sat ISS --closed-loop

The camera follows the mount's own clock (real time, or ×speed for a simulated mount
running by itself). For deterministic runs, run it in the same process as the emulator:
`vs server --emulator --speed max --camera-sim truth.toml` (lockstep).
"""

from __future__ import annotations

import asyncio
import signal
from pathlib import Path
from typing import Annotated

import typer

from astcom_client import AstcomError, Client

from .config_file import load_camera_file
from .device import GuideCameraDevice
from .exceptions import CameraConfigError
from .truth import CameraSite

__all__ = ["app", "main"]

app = typer.Typer(add_completion=False, help=__doc__)


def _fail(message: str, code: int = 2) -> typer.Exit:
    typer.echo(f"guide-camera: error: {message}", err=True)
    return typer.Exit(code)


@app.command()
def run(
    truth: Annotated[Path, typer.Argument(
        help="TOML file: \\[truth] (a satellite's TLE moved along/across, or a star's place) "
        "and \\[camera] settings; docs/guide-camera.md")],
    mount: Annotated[str, typer.Option(
        "--mount", help="ASTCom URL of the mount emulator, e.g. ws://127.0.0.1:8765.")],
    site_file: Annotated[Path, typer.Option(
        "--site-file", envvar="VIRTUALSTAR_SITE",
        help="The site (virtualstar/data/site.toml's layout): where the camera is, its air.")],
    password: Annotated[str | None, typer.Option(
        "--password", envvar="ASTCOM_PASSWORD", help="The mount endpoint's password.")] = None,
    listen: Annotated[str, typer.Option(
        "--listen", help="Where the camera's own ASTCom endpoint listens.")] = "ws://127.0.0.1:8777",
    speed: Annotated[float, typer.Option(
        "--speed", help="Mount seconds per wall second of the mount (1 = real time).")] = 1.0,
) -> None:
    """Run a simulated guide camera beside a mount emulator until Ctrl-C."""
    if not 0 < speed < 1000:
        raise _fail(f"--speed {speed}: expected > 0 and < 1000")
    try:
        site = CameraSite.from_toml(site_file)
        sim_truth, config = load_camera_file(truth, site)
    except CameraConfigError as exc:
        raise _fail(str(exc)) from None

    async def main() -> None:
        async def connect() -> Client:
            return await Client.connect(mount, password=password, name="guide-camera")

        device = GuideCameraDevice(connect, sim_truth, config=config, site=site, speed=speed)
        try:
            url = await device.start(listen)
        except (AstcomError, TimeoutError) as exc:
            raise _fail(f"cannot reach the mount at {mount}: {exc}") from None
        typer.echo(f"guide camera on {url} (frames every {config.period_s:g} s; mount {mount})")
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, stop.set)
        try:
            await stop.wait()
        finally:
            await device.stop()

    try:
        asyncio.run(main())
    except OSError as exc:
        raise _fail(f"cannot listen on {listen}: {exc.strerror or exc}", 1) from None


def main() -> None:
    app()
