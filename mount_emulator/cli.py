"""`mount-emulator`: serve an emulated 10 kHz alt-az mount over ASTCom until interrupted."""

from __future__ import annotations

import asyncio
import ipaddress
import os
import secrets
import signal
import socket
import sys
from datetime import UTC, datetime
from pathlib import Path
from typing import Annotated

import typer

from mount_emulator.config import EmulatorConfig, load_config_file
from mount_emulator.emulator import MountEmulator
from mount_emulator.exceptions import ConfigError, InsecureListen
from mount_emulator.geometry import Geometry

__all__ = ["app", "main"]

app = typer.Typer(add_completion=False, help=__doc__)


def _fail(message: str, code: int = 2) -> typer.Exit:
    typer.echo(f"mount-emulator: error: {message}", err=True)
    return typer.Exit(code)


def parse_speed(text: str) -> float:
    """Return the speed factor of ``--speed`` (``max`` → 0, meaning as fast as possible)."""
    if text.strip().lower() == "max":
        return 0.0
    try:
        value = float(text)
    except ValueError:
        raise ConfigError(f"--speed {text!r}: expected a positive number (1 = real time) or 'max'") from None
    if not value > 0 or value == float("inf"):
        raise ConfigError(f"--speed {text!r}: expected a positive number (1 = real time) or 'max'")
    return value


def parse_utc(text: str) -> int:
    """Return µs since 1970 of an ISO-8601 UTC time (``2026-03-01T20:00:00Z``)."""
    try:
        when = datetime.fromisoformat(text.replace("Z", "+00:00").replace("z", "+00:00"))
    except ValueError:
        raise ConfigError(f"--start {text!r}: expected ISO-8601 UTC such as 2026-03-01T20:00:00Z") from None
    if when.tzinfo is None:
        when = when.replace(tzinfo=UTC)
    delta = when - datetime(1970, 1, 1, tzinfo=UTC)
    return (delta.days * 86_400 + delta.seconds) * 1_000_000 + delta.microseconds


def is_loopback(host: str) -> bool:
    """Return True when ``host`` only resolves to loopback addresses."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        try:
            infos = socket.getaddrinfo(host, None)
        except OSError:
            return False
        return all(ipaddress.ip_address(i[4][0]).is_loopback for i in infos)


def check_listen(host: str, passwords: dict[str, str] | None) -> None:
    """Refuse a non-loopback listen address without a password (raise InsecureListen)."""
    if not passwords and not is_loopback(host):
        raise InsecureListen(f"--host {host} is not a loopback address: give --password "
                             "(or ASTCOM_PASSWORD) before exposing the mount on a network")


@app.command()
def serve(
    host: Annotated[str, typer.Option(help="Address to listen on.")] = "127.0.0.1",
    port: Annotated[int, typer.Option(min=0, max=65535, help="TCP port (0 picks a free one).")] = 8765,
    transport: Annotated[str, typer.Option(help="ws (WebSocket) or tcp.")] = "ws",
    password: Annotated[str | None, typer.Option(
        envvar="ASTCOM_PASSWORD", help="Operator password (read/write/call).")] = None,
    observer_password: Annotated[str | None, typer.Option(
        help="Observer password (read and stream only).")] = None,
    start: Annotated[str | None, typer.Option(
        help="Mount time at start, ISO-8601 UTC (default: now).")] = None,
    speed: Annotated[str, typer.Option(
        help="1 = real time, X = X times real time, 'max' = as fast as possible.")] = "1",
    config: Annotated[Path | None, typer.Option(
        help="TOML file of parameters (\\[axis.az] kp = ...), \\[emulator] and \\[geometry].")] = None,
    geometry: Annotated[Path | None, typer.Option(
        help="TOML/JSON file of the hidden TPOINT terms (arcsec).")] = None,
    seed: Annotated[int | None, typer.Option(
        help="Draw the hidden geometry from this seed (default: a random seed).")] = None,
) -> None:
    """Serve the emulated mount; print the URL; run until Ctrl-C or SIGTERM."""
    try:
        if transport not in ("ws", "tcp"):
            raise ConfigError(f"--transport {transport!r}: expected ws or tcp")
        if geometry is not None and seed is not None:
            raise ConfigError("give either --geometry FILE or --seed N, not both")
        cfg = load_config_file(config) if config is not None else EmulatorConfig()
        cfg.speed = parse_speed(speed)
        cfg.start_us = parse_utc(start) if start else None
        passwords = {}
        if password:
            passwords["operator"] = password
        if observer_password:
            passwords["observer"] = observer_password
        cfg.passwords = passwords or None
        check_listen(host, cfg.passwords)
        if geometry is not None:
            cfg.geometry = Geometry.from_file(geometry)
        elif seed is not None or config is None or cfg.geometry == Geometry():
            cfg.geometry = Geometry.from_seed(seed if seed is not None else secrets.randbits(32))
        emulator = MountEmulator(cfg)
    except (ConfigError, InsecureListen) as exc:
        raise _fail(str(exc)) from None
    url_host = f"[{host}]" if ":" in host else host
    try:
        asyncio.run(_serve(emulator, f"{transport}://{url_host}:{port}"))
    except OSError as exc:
        raise _fail(f"cannot listen on {host}:{port}: {exc.strerror or exc}", 1) from None


async def _serve(emulator: MountEmulator, url: str) -> None:
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    bound = await emulator.start(url)
    mode = "real time" if emulator.speed == 1 else (
        "as fast as possible" if emulator.speed == 0 else f"{emulator.speed:g}x real time")
    print(f"mount-emulator serving on {bound} ({mode}, mount time {emulator.mount_time_iso()})",
          flush=True)
    try:
        await stop.wait()
    finally:
        await emulator.stop()
        print("mount-emulator stopped", flush=True)


def main() -> None:
    """Entry point of the ``mount-emulator`` console script."""
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    app(prog_name="mount-emulator")
    sys.exit(0)
