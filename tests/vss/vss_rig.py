"""A running emulator + VSS on an event loop in a background thread, for CLI tests.

The `vs` commands run `asyncio.run` themselves, so the server side lives on its
own loop in a thread; tests talk to it through the CLI (CliRunner), through
`VssClient`, and to the emulator directly through an ASTCom `Client` (the
independent view of where the encoders are).

The rig runs in lockstep simulated time (`virtualstar.lockstep`): the VSS and the
emulator share one clock, so however loaded the host, the server is never late.
A pace caps the clock (×PACE real time) so that mount time does not race ahead
while a test's own code runs between commands. `Rig(realtime=True)` runs the
emulator on the host clock instead, over a WebSocket, as with a real mount.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import signal
import socket
import subprocess
import sys
import threading
from dataclasses import dataclass
from typing import Any

import forkserver
import numpy as np

from astcom_client import Client
from virtualstar.astro import Site
from virtualstar.launcher import start_emulator
from virtualstar.lockstep import LockstepClock, LockstepEventLoop
from virtualstar.server import build_server

PACE = 50.0  # mount seconds per wall second at most, while tests talk to the rig
# An observing program of three bright stars, 2 minutes each (vs plan's TOML), up at night in
# May from the default site: the planning and panel tests plan it for their own windows.
STARS_PROGRAM = """
[defaults]
duration_s = 120
min_el_deg = 20
sun_max_el_deg = -6
[[target]]
star = "Arcturus"
priority = 3
[[target]]
star = "Deneb"
priority = 2
[[target]]
star = "Vega"
"""


class Rig:
    """Emulator + VSS, started on a private event loop (lockstep unless `realtime`)."""

    def __init__(self, *, start_us: int | None, site: Site | None = None,
                 pace: float | None = PACE, realtime: bool = False,
                 emulator_options: dict[str, Any] | None = None,
                 **telescope_options: Any) -> None:
        self.site = site
        self.options = telescope_options
        self.emulator_options = emulator_options or {}
        self.realtime = realtime
        if realtime:
            self.clock = None
            self.loop = asyncio.new_event_loop()
        else:
            assert start_us is not None
            self.clock = LockstepClock(start_us, pace=pace)
            self.loop = LockstepEventLoop(self.clock)
        self.start_us = start_us
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self.thread.start()
        self.emulator = None
        self.server = None
        self.url = ""

    def run(self, coro, timeout_s: float = 120.0):
        """Run a coroutine on the rig's loop and return its result."""
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(timeout_s)

    def start(self, listen: str = "ws://127.0.0.1:0") -> Rig:
        async def go() -> None:
            self.emulator = await start_emulator(start_us=self.start_us, clock=self.clock,
                                                 **self.emulator_options)
            await self.start_server(listen)

        self.run(go())
        return self

    async def start_server(self, listen: str = "ws://127.0.0.1:0") -> str:
        emu = self.emulator
        connector = None
        if self.clock is not None:
            async def connector():
                return await emu.connect_in_memory(name="virtualstar-server")
        self.server = build_server(mount_url=emu.url if self.realtime else "in-process emulator",
                                   site=self.site, clock=self.clock, connector=connector,
                                   **self.options)
        self.url = await self.server.start(listen)
        await self.server.telescope.link.wait_connected(30.0)
        await self.server.telescope.first_samples(30.0)
        return self.url

    async def cut_line(self) -> None:
        """Break the connection between the VSS and the mount, as a failed network would."""
        await self.emulator.cut_in_memory()

    async def mount_sleep(self, mount_s: float) -> None:
        """Let `mount_s` seconds of mount time pass (on the rig's loop)."""
        await self.clock.sleep(mount_s)

    async def mount_read(self, names: list[str]) -> tuple[dict[str, Any], int]:
        """Read emulator variables directly (one tick); return (values, mount time µs)."""
        async with await Client.connect(self.emulator.url) as c:
            values, _tick, t_us = await c.read_at(names)
        return values, int(t_us)

    async def mount_write(self, values: dict[str, Any]) -> None:
        async with await Client.connect(self.emulator.url) as c:
            await c.write(values)

    def close(self) -> None:
        async def stop() -> None:
            if self.server is not None:
                await self.server.close()
            if self.emulator is not None:
                await self.emulator.stop()

        try:
            self.run(stop(), 30.0)
        finally:
            self.loop.call_soon_threadsafe(self.loop.stop)
            self.thread.join(10.0)
            self.loop.close()


def run_lockstep_scenario(start_iso: str, scenario, *, site: Site | None = None,
                          pace: float | None = None, **options: Any):
    """Run `await scenario(vss, clock)` on a fresh emulator + VSS in lockstep, in this thread.

    Nothing else shares the loop and the scenario talks to the server in-process, so
    the run is the same on every host. Returns what the scenario returns.
    """
    from virtualstar.astro import UtcTimes, load_site
    from virtualstar.launcher import embedded_vss
    from virtualstar.lockstep import run_lockstep

    clock = LockstepClock(int(UtcTimes.from_iso([start_iso]).to_unix_us()[0]), pace=pace)

    async def main():
        async with embedded_vss(clock=clock, site=site or load_site(), **options) as vss:
            return await scenario(vss, clock)

    return run_lockstep(main(), clock)


def mapping_without(tmp_path, *functions: str):
    """The bundled emulator mapping with `functions` roles removed, as a file in `tmp_path`
    (a controller that lacks them, e.g. `traj_replace`)."""
    import json
    from importlib import resources

    doc = json.loads(resources.files("virtualstar").joinpath(
        "data/emulator-mapping.json").read_text("utf-8"))
    for role in functions:
        del doc["functions"][role]
    path = tmp_path / f"without-{'-'.join(functions)}.json"
    path.write_text(json.dumps(doc))
    return path


async def read_emulator(vss, names: list[str]) -> tuple[dict[str, Any], int]:
    """Read emulator variables over a connection of the test's own (values, mount time µs)."""
    client = await vss.emulator.connect_in_memory(name="test-observer")
    try:
        values, _tick, t_us = await client.read_at(names)
    finally:
        await client.close()
    return values, int(t_us)


ENCODERS = ["axis.az.position", "axis.el.position"]


@dataclass
class EncoderSamples:
    """Encoder readings straight from the emulator: mount times (µs) and angles (rad)."""

    t_us: np.ndarray
    az_rad: np.ndarray
    el_rad: np.ndarray

    @property
    def az_deg(self) -> np.ndarray:
        return np.degrees(self.az_rad) % 360.0

    @property
    def el_deg(self) -> np.ndarray:
        return np.degrees(self.el_rad)


async def sample_encoders(vss, clock, every_s: float, *, until=None, reads: int | None = None,
                          tracking_only: bool = False) -> EncoderSamples:
    """Read the encoders straight from the emulator every `every_s` mount seconds.

    Until the future `until` is done, or for `reads` reads; `tracking_only` keeps only
    readings with the mount TRACKING and stops at the first other state after them.
    """
    rows: list[tuple[int, float, float]] = []
    names = [*ENCODERS, "mount.state_name"]
    k = 0
    while (until is None or not until.done()) and (reads is None or k < reads):
        k += 1
        values, t_us = await read_emulator(vss, names)
        if not tracking_only or values["mount.state_name"] == "TRACKING":
            rows.append((t_us, values[ENCODERS[0]], values[ENCODERS[1]]))
        elif rows:
            break
        await clock.sleep(every_s)
    t, az, el = (np.array(c) for c in zip(*rows, strict=True)) if rows else ([],) * 3
    return EncoderSamples(np.asarray(t, np.int64), np.asarray(az, float), np.asarray(el, float))


@contextlib.asynccontextmanager
async def encoder_stream(vss, rate_hz: float):
    """Stream the encoders from the emulator at `rate_hz` over a connection of the test's
    own for the duration of the block; yields a list that `.result()` makes samples of."""
    client = await vss.emulator.connect_in_memory(name="test-encoders")
    packets: list[Any] = []
    stream = await client.stream(ENCODERS, rate_hz)
    stream.on_packet(packets.append)

    class Recording(list):
        def result(self) -> EncoderSamples:
            if not packets:
                return EncoderSamples(np.array([], np.int64), np.array([]), np.array([]))
            return EncoderSamples(np.concatenate([p.t_us for p in packets]),
                                  np.concatenate([p.column(ENCODERS[0]) for p in packets]),
                                  np.concatenate([p.column(ENCODERS[1]) for p in packets]))

    try:
        yield Recording()
    finally:
        await stream.stop()
        await client.close()


@dataclass
class ServerProcess:
    """A `vs server` in its own process: its URL, the line it printed once listening, and
    (after the block) its exit code and the rest of its output."""

    url: str
    line: str
    proc: subprocess.Popen
    out: str = ""
    err: str = ""

    @property
    def returncode(self) -> int | None:
        return self.proc.returncode


@contextlib.contextmanager
def vs_server_process(*args: str):
    """Run `vs server ARGS --listen ws://127.0.0.1:PORT` (a free port) until the block ends,
    then stop it with SIGTERM as a user's Ctrl-C would."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        url = f"ws://127.0.0.1:{s.getsockname()[1]}"
    if "--emulator" in args and "--endpoint-port" not in args:
        args = (*args, "--endpoint-port", "0")  # its ASTCom endpoint on a free port too
    proc = forkserver.popen(
        [sys.executable, "-c", "from virtualstar.cli.main import main; main()", "server",
         *args, "--listen", url],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"})
    server = ServerProcess(url, "", proc)
    try:
        server.line = proc.stdout.readline()
        assert url in server.line, (server.line, proc.stderr.read() if proc.poll() is not None
                                    else "")
        yield server
    finally:
        proc.send_signal(signal.SIGTERM)
        server.out, server.err = proc.communicate(timeout=30)
