"""A minimal client written only from docs/astcom-protocol.md talks to a live Endpoint.

The client half of this file imports none of astcom_client: raw WebSocket / TCP,
msgpack, hmac and numpy, following the document section by section. Only the endpoint
(the thing under test) comes from our code.
"""

import asyncio
import hashlib
import hmac
import math
import os
import struct

import msgpack
import numpy as np
import pytest
from astcom_helpers import PASSWORDS, run, served
from websockets.asyncio.client import connect as ws_connect

# §2.1 dtype codes
DTYPES = {0: "?", 1: "<i1", 2: "<i2", 3: "<i4", 4: "<i8", 5: "<u1", 6: "<u2", 7: "<u4",
          8: "<u8", 9: "<f4", 10: "<f8"}


def ext_hook(code: int, data: bytes):
    if code == 1:  # §2.1 typed array
        dtype, ndim = data[0], data[1]
        shape = struct.unpack_from(f"<{ndim}I", data, 4)
        header = math.ceil((4 + 4 * ndim) / 8) * 8
        return np.frombuffer(data, DTYPES[dtype], math.prod(shape), header).reshape(shape)
    if code == 2:  # §2.2 timestamp
        return ("t_us", struct.unpack("<q", data)[0])
    raise ValueError(code)


class SpecClient:
    """Frames per §1, requests per §3, handshake per §5."""

    def __init__(self, scheme: str, url: str) -> None:
        self.scheme, self.url, self.seq, self.packets = scheme, url, 0, []

    async def open(self) -> None:
        if self.scheme == "ws":
            self.ws = await ws_connect(self.url, compression=None, proxy=None)
        else:
            host, port = self.url.removeprefix("tcp://").rsplit(":", 1)
            self.reader, self.writer = await asyncio.open_connection(host, int(port))

    async def send(self, frame) -> None:
        data = msgpack.packb(frame, use_bin_type=True)
        if self.scheme == "ws":
            await self.ws.send(data)
        else:
            self.writer.write(struct.pack(">I", len(data)) + data)
            await self.writer.drain()

    async def recv(self):
        if self.scheme == "ws":
            data = await self.ws.recv()
        else:
            (size,) = struct.unpack(">I", await self.reader.readexactly(4))
            data = await self.reader.readexactly(size)
        return msgpack.unpackb(data, raw=False, ext_hook=ext_hook)

    async def call(self, op: str, args: dict | None = None) -> dict:
        self.seq += 1
        await self.send([op, self.seq, args or {}])
        while True:
            frame = await self.recv()
            if frame[0] == "DATA":
                self.packets.append(frame)
                continue
            kind, seq, body = frame
            assert seq == self.seq
            if kind == "ERR":
                raise RuntimeError(f"{body['code']} {body['message']}")
            return body

    async def login(self, password: str) -> dict:
        hello = await self.call("HELLO", {"version": "1.0", "client": "from-the-spec"})
        assert hello["auth"] == "hmac-sha256" and len(hello["nonce"]) == 32
        key, sn, cn = password.encode("utf-8"), hello["nonce"], os.urandom(32)
        mac = hmac.new(key, b"ASTCom-1 client\x00" + sn + cn, hashlib.sha256).digest()
        reply = await self.call("AUTH", {"cnonce": cn, "mac": mac})
        proof = hmac.new(key, b"ASTCom-1 server\x00" + sn + cn, hashlib.sha256).digest()
        assert reply["proof"] == proof
        return {**hello, **reply}

    async def next_packet(self):
        while not self.packets:
            frame = await self.recv()
            if frame[0] == "DATA":
                self.packets.append(frame)
        return self.packets.pop(0)


@pytest.mark.parametrize("scheme", ["ws", "tcp"])
def test_a_client_written_from_the_spec_authenticates_lists_reads_and_streams(scheme: str) -> None:
    async def main() -> None:
        async with served(f"{scheme}://127.0.0.1:0", realtime=True) as (device, _, url):
            client = SpecClient(scheme, url)
            await client.open()
            session = await client.login(PASSWORDS["observer"])
            assert session["role"] == "observer" and session["loop_rate_hz"] == 1000.0

            entries = (await client.call("LIST"))["entries"]
            by_name = {e["name"]: e for e in entries}
            assert by_name["gains"]["type"] == "f64[3]" and by_name["counter"]["kind"] == "signal"

            while (await client.call("PING"))["tick"] < 0:  # wait for the device's first block
                await asyncio.sleep(0.01)
            msg = (await client.call("DEFINE", {"names": ["counter", "gains", "label"]}))["msg"]
            read = await client.call("READ", {"msg": msg})
            counter, gains, label = read["values"]
            assert 0 <= counter <= read["tick"] and label == "example"
            assert gains.dtype == np.float64 and gains.tolist() == device.gains.tolist()

            sig = (await client.call("DEFINE", {"names": ["wave.sine", "counter"]}))["msg"]
            layout = await client.call("STREAM_START", {"msg": sig, "rate_hz": 250})
            assert layout["columns"] == ["wave.sine", "counter"]
            assert layout["dtypes"] == ["f64", "i64"] and layout["groups"] == [[0], [1]]
            first = await client.next_packet()
            second = await client.next_packet()
            for packet in (first, second):
                _, m, seq, tick0, t0, period_us, period_ticks, n, arrays = packet
                ticks = tick0 + period_ticks * np.arange(n)
                assert m == sig and period_ticks == 4 and period_us == 4000.0
                assert np.all(ticks % 4 == 0)
                np.testing.assert_array_equal(arrays[1][:, 0], ticks)  # counter == tick
                np.testing.assert_allclose(arrays[0][:, 0],
                                           np.sin(2 * np.pi * 5.0 * ticks / 1000.0), atol=1e-12)
                t_us = t0 + np.round(np.arange(n) * period_us)
                np.testing.assert_array_equal(t_us, device.start_t_us + ticks * 1000)
            assert second[2] == first[2] + 1 and second[3] == first[3] + first[7] * first[6]

            with pytest.raises(RuntimeError, match="^403"):
                await client.call("WRITE", {"msg": msg, "values": [1, [1, 2, 3], "x"]})
            assert "t_us" in (await client.call("PING"))["t_us"]
            await client.call("BYE")
    run(main())
