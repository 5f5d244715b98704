"""The Relay (astcom_client/relay.py) against a scripted device that speaks §11 itself.

The device end is a TCP server written here from the spec's link table (not the C
library), so each test can make the device do exactly one thing: answer late, reboot,
stay silent, refuse a channel. A WebSocket client stands in front of the Relay.
"""

from __future__ import annotations

import asyncio
import contextlib
import struct

import msgpack
from astcom_helpers import run
from websockets.asyncio.client import connect

from astcom_client.link import LinkKind, LinkReader, encode_link_frame, link_hello_body
from astcom_client.relay import Relay, RelayConfig

CHANNELS, MAX_FRAME = 2, 4096


class ScriptedDevice:
    """The device end of a link over TCP: records what the Relay sends, sends what it is told."""

    def __init__(self) -> None:
        self.frames: asyncio.Queue = asyncio.Queue()
        self.writer: asyncio.StreamWriter | None = None
        self.connected = asyncio.Event()
        self.pong = True

    async def start(self) -> str:
        self.server = await asyncio.start_server(self._serve, "127.0.0.1", 0)
        return f"127.0.0.1:{self.server.sockets[0].getsockname()[1]}"

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.writer = writer
        self.connected.set()
        link = LinkReader(1 << 20)
        while data := await reader.read(65536):
            for frame in link.feed(data):
                if frame.kind == LinkKind.PING:
                    if self.pong:
                        self.send(0, LinkKind.PONG, frame.body)
                    continue
                await self.frames.put(frame)

    def send(self, chan: int, kind: int, body: bytes = b"") -> None:
        assert self.writer is not None
        self.writer.write(encode_link_frame(chan, kind, body))

    def hello(self, token: int) -> None:
        self.send(0, LinkKind.HELLO, link_hello_body(CHANNELS, MAX_FRAME, token))

    async def next(self, kind: int) -> object:
        while True:
            frame = await asyncio.wait_for(self.frames.get(), 5)
            if frame.kind == kind:
                return frame

    def close(self) -> None:
        self.server.close()
        if self.writer is not None:
            self.writer.close()


@contextlib.asynccontextmanager
async def relay_on(device: ScriptedDevice, **config):
    """A Relay on the scripted device; the device answers the Relay's first HELLO at once."""
    where = await device.start()
    relay = Relay(RelayConfig(tcp=where, listen=("ws://127.0.0.1:0",), **config))
    starting = asyncio.create_task(relay.start())
    await device.connected.wait()
    first = await device.next(LinkKind.HELLO)
    device.hello(struct.unpack_from("<I", first.body, 7)[0])
    await starting
    try:
        yield relay
    finally:
        await relay.close()
        device.close()


async def ws_client(relay: Relay, **options):
    return await connect(relay.urls[0], proxy=None, compression=None, **options)


@contextlib.asynccontextmanager
async def one_client(client_options: dict | None = None, **config):
    """A scripted device, a Relay on it, and one client whose channel the device opened."""
    device = ScriptedDevice()
    async with relay_on(device, **config) as relay:
        ws = await ws_client(relay, **(client_options or {}))
        await device.next(LinkKind.OPEN)
        yield device, relay, ws


async def next_message(ws, timeout_s: float = 5.0):
    return msgpack.unpackb(await asyncio.wait_for(ws.recv(), timeout_s))


def test_the_answer_to_the_relays_hello_is_not_taken_for_a_reboot_even_after_a_stale_one():
    """A device that booted before the Relay left its boot HELLO (token 0) in the line; the
    Relay then asks with its own HELLO, and the answer may come after clients arrived."""
    async def main():
        device = ScriptedDevice()
        where = await device.start()
        relay = Relay(RelayConfig(tcp=where, listen=("ws://127.0.0.1:0",)))
        starting = asyncio.create_task(relay.start())
        await device.connected.wait()
        asked = await device.next(LinkKind.HELLO)
        token = struct.unpack_from("<I", asked.body, 7)[0]
        assert token != 0
        device.hello(0)  # the stale boot announcement
        await starting
        try:
            ws = await ws_client(relay)
            opened = await device.next(LinkKind.OPEN)
            device.hello(token)  # the late answer: not a reboot
            device.send(opened.chan, LinkKind.DATA, msgpack.packb(["OK", 1, {}]))
            assert await next_message(ws) == ["OK", 1, {}]
            await ws.close()
        finally:
            await relay.close()
            device.close()
    run(main())


def test_a_device_that_reboots_closes_every_client_with_503():
    async def main():
        async with one_client() as (device, _, ws):
            device.hello(0)  # booted again: it has forgotten every channel
            reply = await next_message(ws)
            assert reply[0] == "ERR" and reply[1] is None and reply[2]["code"] == 503
            assert "restarted" in reply[2]["message"]
    run(main())


def test_a_silent_device_is_a_lost_link_and_later_clients_are_told_so():
    async def main():
        async with one_client(ping_interval_s=0.1, link_timeout_s=0.5) as (device, relay, ws):
            device.pong = False
            reply = await next_message(ws)
            assert reply[2]["code"] == 503 and "has not answered" in reply[2]["message"]
            late = await ws_client(relay)
            reply = await next_message(late)
            assert reply[2]["code"] == 503 and "down" in reply[2]["message"]
    run(main())


def test_clients_beyond_the_devices_channels_get_429():
    async def main():
        device = ScriptedDevice()
        async with relay_on(device) as relay:
            held = [await ws_client(relay) for _ in range(CHANNELS)]
            for _ in held:
                await device.next(LinkKind.OPEN)
            extra = await ws_client(relay)
            reply = await next_message(extra)
            assert reply[2]["code"] == 429 and f"at most {CHANNELS}" in reply[2]["message"]
    run(main())


def test_a_frame_over_the_devices_limit_is_refused_by_the_relay_with_413():
    async def main():
        async with one_client() as (device, _, ws):
            await ws.send(b"\x00" * (MAX_FRAME + 1))
            reply = await next_message(ws)
            assert reply[2]["code"] == 413 and str(MAX_FRAME) in reply[2]["message"]
            # the device never saw it, and the channel is given back
            assert (await device.next(LinkKind.CLOSE)).chan == 1
    run(main())


def test_the_device_closing_a_channel_closes_that_client_only_after_its_last_frame():
    async def main():
        device = ScriptedDevice()
        async with relay_on(device) as relay:
            a, b = await ws_client(relay), await ws_client(relay)
            chan_a = (await device.next(LinkKind.OPEN)).chan
            await device.next(LinkKind.OPEN)
            device.send(chan_a, LinkKind.DATA, msgpack.packb(["ERR", None, {"code": 408}]))
            device.send(chan_a, LinkKind.CLOSE, struct.pack("<H", 408) + b"not authenticated")
            assert (await next_message(a))[2]["code"] == 408
            await asyncio.wait_for(a.wait_closed(), 5)
            await b.ping()  # the other client is untouched
    run(main())


def test_a_client_that_does_not_read_loses_its_oldest_packets_never_a_reply():
    async def main():
        # the client's own library keeps one message: what it does not read stays in the Relay
        async with one_client({"max_queue": 1}, queue_packets=4) as (device, relay, ws):
            chan = 1
            payload = b"\x01" * 900_000  # large packets: the sockets' buffers fill quickly
            for seq in range(30):
                device.send(chan, LinkKind.DATA,
                            msgpack.packb(["DATA", 1, seq, 0, 0, 1.0, 1, 1, [payload]]))
            device.send(chan, LinkKind.DATA, msgpack.packb(["OK", 7, {}]))
            await device.writer.drain()
            await asyncio.sleep(1.0)  # the Relay has it all; the client has read nothing
            frames = []
            while True:
                frame = await next_message(ws)
                frames.append(frame)
                if frame[0] == "OK":
                    break
            return frames, relay

    frames, relay = run(main(), timeout_s=60)
    seqs = [f[2] for f in frames if f[0] == "DATA"]
    assert frames[-1] == ["OK", 7, {}]  # the reply, after every packet sent before it
    assert seqs == sorted(seqs) and seqs[-1] == 29  # the newest kept, in order
    assert len(seqs) < 30  # the oldest beyond the queue (and the sockets' buffers) dropped
