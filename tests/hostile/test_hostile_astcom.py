"""The ASTCom Endpoint under the same attacks: a flood never read before authentication,
password guessing from many addresses; and the emulator logs every wrong password."""

from __future__ import annotations

import asyncio
import contextlib
import os
import threading

import msgpack
from hostile_peers import FrameReader, flood_never_read, ws_frame, ws_open

from astcom_client import Client, Endpoint, EndpointConfig
from astcom_client.example_device import ExampleDevice
from astcom_client.exceptions import AuthenticationFailed
from mount_emulator.config import EmulatorConfig
from mount_emulator.emulator import MountEmulator

PASSWORDS = {"operator": "astcom-op-secret", "observer": "astcom-obs-secret"}
HELLO = msgpack.packb(["HELLO", 1, {"version": "1.0", "client": "stranger"}])


class ServedDevice:
    """An example device served on ws://127.0.0.1:0 from an event loop in a thread."""

    def __init__(self, **config) -> None:
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self.thread.start()
        self.failures: list[tuple[str, int]] = []
        self.url = self.run(self._start(config))

    def run(self, coro, timeout_s: float = 60.0):
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(timeout_s)

    async def _start(self, config) -> str:
        self.device = ExampleDevice(loop_rate_hz=1000.0)
        self.endpoint = Endpoint(self.device.collection, EndpointConfig(
            loop_rate_hz=1000.0, passwords=PASSWORDS, **config))
        self.endpoint.on_auth_failure = lambda peer, f: self.failures.append((peer, f.failures))
        self.task = asyncio.get_running_loop().create_task(self.device.run(self.endpoint))
        return await self.endpoint.serve("ws://127.0.0.1:0")

    def close(self) -> None:
        async def stop() -> None:
            self.task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self.task
            await self.endpoint.close()

        self.run(stop())
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(10)


def test_a_peer_that_floods_pings_before_authenticating_and_never_reads_stops_being_read():
    served = ServedDevice()
    try:
        ping = msgpack.packb(["PING", 2, {"pad": "x" * 600}])
        sock, flood = flood_never_read(served.url, 50_000, give_up_s=3.0, text=ping,
                                       opcode=2, first=ws_frame(HELLO, opcode=2))

        async def legit() -> dict:
            async with await Client.connect(served.url, password=PASSWORDS["observer"]) as c:
                return await c.read(["counter"])

        values = served.run(legit())
        stats = served.endpoint.stats()
        sock.close()
    finally:
        served.close()
    assert flood.sent < flood.wanted, "the endpoint read the whole flood: no back-pressure"
    assert "counter" in values
    assert stats["pending"] <= 1


def guess_astcom(url: str, source: str, tries: int) -> list[int]:
    """`tries` connections from `source`, each with one wrong password; return the codes."""
    codes = []
    for _ in range(tries):
        with contextlib.suppress(ConnectionError, OSError):
            sock, rest = ws_open(url, source=source)
            reader = FrameReader(sock, rest)
            sock.sendall(ws_frame(HELLO, opcode=2))
            while (frame := reader.frame())[0] != 2:
                pass
            sock.sendall(ws_frame(msgpack.packb(["AUTH", 2, {
                "cnonce": os.urandom(16), "mac": os.urandom(32), "role": None}]), opcode=2))
            while (frame := reader.frame())[0] != 2:
                pass
            reply = msgpack.unpackb(frame[1])
            codes.append(reply[2]["code"] if reply[0] == "ERR" else 200)
            sock.close()
    return codes


def test_password_guesses_on_the_endpoint_are_throttled_per_address_and_reported():
    served = ServedDevice()
    sources = [f"127.0.0.{k}" for k in range(2, 8)]
    results: dict[str, list[int]] = {}
    try:
        threads = [threading.Thread(target=lambda s=s: results.__setitem__(
            s, guess_astcom(served.url, s, 12))) for s in sources]
        for t in threads:
            t.start()
        for t in threads:
            t.join(300)

        async def legit() -> str:
            async with await Client.connect(served.url, password=PASSWORDS["operator"]) as c:
                return str(c.role)

        role = served.run(legit())
        throttle = served.endpoint.throttle
    finally:
        served.close()
    codes = [c for cs in results.values() for c in cs]
    assert set(codes) <= {401, 429}, codes
    assert codes.count(429) > 0  # refused unchecked
    assert codes.count(401) == len(served.failures) == throttle.failures  # each one reported
    reported = {peer.rpartition(":")[0] for peer, _ in served.failures}
    assert reported <= set(sources)
    assert role == "operator"  # another address logs in all the same


def test_the_emulator_logs_every_wrong_password_as_an_auth_warning():
    async def run() -> list[dict]:
        emu = MountEmulator(EmulatorConfig(start_us=1_767_225_600_000_000,
                                           passwords={"operator": "emu-secret"}))
        await emu.start(None, run_loop=False)
        try:
            for guess in ("a", "b"):
                with contextlib.suppress(AuthenticationFailed):
                    await Client.open(emu.endpoint.connect_in_memory(), password=guess,
                                      name="guesser")
            return [e.as_dict() for e in emu.log.since(0)]
        finally:
            await emu.stop()

    events = asyncio.run(run())
    auth = [e for e in events if e["kind"] == "auth"]
    assert len(auth) == 2 and all(e["level"] == "warning" for e in auth)
    assert "wrong password" in auth[0]["message"] and "1 in a row" in auth[0]["message"]
    assert "2 in a row" in auth[1]["message"]
