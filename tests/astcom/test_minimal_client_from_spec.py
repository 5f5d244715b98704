"""A minimal client written only from docs/astcom-protocol.md talks to a live Endpoint.

The client half of this file imports none of astcom_client: raw WebSocket / TCP,
msgpack, hmac and numpy, following the document section by section. Only the endpoint
(the thing under test) comes from our code: the Python Endpoint, the C device over TCP
(its sanitizer build) and the C device through the Relay over a pty pair.
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
from astcom_helpers import PASSWORDS, run
from device_impls import EXAMPLE_GAINS, SOCKET_IMPLS, serve_impl
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


@pytest.mark.parametrize(("impl", "scheme"), SOCKET_IMPLS)
def test_a_client_written_from_the_spec_authenticates_lists_reads_and_streams(impl: str,
                                                                              scheme: str) -> None:
    async def main() -> None:
        async with serve_impl(impl, scheme=scheme, realtime=True) as dut:
            client = SpecClient(scheme, dut.url)
            start_t_us = await dut.start_t_us(1000.0)
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
            assert gains.dtype == np.float64 and gains.tolist() == EXAMPLE_GAINS

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
                np.testing.assert_array_equal(t_us, start_t_us + ticks * 1000)
            assert second[2] == first[2] + 1 and second[3] == first[3] + first[7] * first[6]

            with pytest.raises(RuntimeError, match="^403"):
                await client.call("WRITE", {"msg": msg, "values": [1, [1, 2, 3], "x"]})
            assert "t_us" in (await client.call("PING"))["t_us"]
            await client.call("BYE")
    run(main())


@pytest.mark.parametrize(("impl", "scheme"), SOCKET_IMPLS)
def test_a_client_written_from_the_spec_meets_the_settled_edges(impl: str, scheme: str) -> None:
    """The answers §3, §5, §6, §7 and §8 now give, checked from the spec client's side."""
    async def main() -> None:
        async with serve_impl(impl, scheme=scheme) as dut:
            url = dut.url
            # §5: version syntax; the reply states the endpoint's own version
            for version in ("1", "1.7"):
                probe = SpecClient(scheme, url)
                await probe.open()
                assert (await probe.call("HELLO", {"version": version}))["version"] == "1.0"
                await probe.call("BYE")
            client = SpecClient(scheme, url)
            await client.open()
            # §3: an optional field may be nil; §5: the limits name max_clients, max_pending
            client.seq += 1
            await client.send(["HELLO", client.seq, {"version": "1.0", "client": None}])
            hello = (await client.recv())[2]
            limits = hello["limits"]
            assert isinstance(hello["loop_rate_hz"], float)
            assert limits["max_clients"] == 32 and limits["max_pending"] == 8
            key, sn, cn = PASSWORDS["operator"].encode(), hello["nonce"], os.urandom(32)
            mac = hmac.new(key, b"ASTCom-1 client\x00" + sn + cn, hashlib.sha256).digest()
            await client.call("AUTH", {"cnonce": cn, "mac": mac, "role": None})
            assert (await client.call("LIST", {"prefix": None}))["entries"]

            # §3: an ERR about an invalid seq carries nil
            await client.send(["PING", -1, {}])
            assert (await client.recv())[:2] == ["ERR", None]
            # §8: the frame's array is level 1; 16 levels pass, 17 are refused (413, closed)
            deep = 0
            for _ in range(16 - 2):  # frame (1) and args (2) already count
                deep = [deep]
            client.seq += 1
            await client.send(["PING", client.seq, {"ignored": deep}])
            assert (await client.recv())[0] == "OK"
            # §6: the slowest stream is one sample every 2^32 ticks
            msg = (await client.call("DEFINE", {"names": ["counter"]}))["msg"]
            with pytest.raises(RuntimeError, match="^422"):
                await client.call("STREAM_START", {"msg": msg, "rate_hz": 1000 / 2**33})
            # §5: errors of codes other than 400/409 do not count toward the 8
            for _ in range(10):
                with pytest.raises(RuntimeError, match="^404"):
                    await client.call("READ", {"msg": 999_999})
            # ... the 400s and 409s do, all of them: the 8th is answered, then the close
            errors = 1  # the PING with seq -1 above
            for _ in range(6):
                with pytest.raises(RuntimeError, match="^(400|409)"):
                    if errors % 2:
                        await client.call("HELLO", {"version": "1.0"})  # 409 once READY
                    else:
                        await client.call("FLY")  # 400: unknown OP
                errors += 1
            assert (await client.call("PING"))["tick"] is not None  # 7 so far: still open
            with pytest.raises(RuntimeError, match="^400"):
                await client.call("FLY")  # the 8th
            from websockets.exceptions import ConnectionClosed

            with pytest.raises((ConnectionClosed, asyncio.IncompleteReadError)):
                await client.call("PING")  # the endpoint closed after the 8th

            # §7: role before lookup: an observer's WRITE to an unknown message is 403
            observer = SpecClient(scheme, url)
            await observer.open()
            await observer.login(PASSWORDS["observer"])
            with pytest.raises(RuntimeError, match="^403"):
                await observer.call("WRITE", {"msg": 123_456, "values": [1]})
            # §7: 17 levels: 413, then the endpoint closes
            deeper = 0
            for _ in range(17 - 2):
                deeper = [deeper]
            observer.seq += 1
            await observer.send(["PING", observer.seq, {"ignored": deeper}])
            reply = await observer.recv()
            assert reply[0] == "ERR" and reply[2]["code"] == 413
    run(main())
