"""Malformed, oversized, early or excessive requests get a reason; nothing else breaks.

Each test runs against every device implementation (tests/astcom/device_impls.py): the
Python Endpoint, the C device (sanitizer build) over TCP and through the Relay.
"""

import asyncio
import struct

import msgpack
import pytest
from astcom_helpers import PASSWORDS, RawPeer, run
from device_impls import ALL_IMPLS, SOCKET_IMPLS, serve_impl

from astcom_client import Client, IncompatibleVersion, TooMany
from astcom_client.protocol import MAX_PROTOCOL_ERRORS


async def raw_peer(dut) -> RawPeer:
    return RawPeer(await dut.connect())


impls = pytest.mark.parametrize("impl", ALL_IMPLS)


def error_code(frame) -> int:
    assert frame is not None and frame[0] == "ERR", frame
    return frame[2]["code"]


@impls
def test_garbage_before_authentication_gets_an_error_then_the_connection_closes(impl: str) -> None:
    async def main() -> None:
        async with serve_impl(impl) as dut:
            peer = await raw_peer(dut)
            await peer.send_raw(b"\xc1\xc1 not msgpack")
            assert error_code(await peer.recv()) == 400
            assert await peer.recv() is None
            async with await dut.client() as client:  # the endpoint still serves
                assert await client.invoke("math.add", 1.0, 1.0) == 2.0
    run(main())


@pytest.mark.parametrize(("impl", "scheme"), SOCKET_IMPLS)
def test_a_peer_cut_off_in_the_middle_of_a_burst_still_reads_why(impl: str, scheme: str) -> None:
    """The endpoint stops reading at the error, but the peer's later frames are already on
    their way: closing with them unread would reset the connection (TCP) or stall the
    closing handshake (WebSocket), and the peer would not learn why it was cut off."""
    async def main() -> None:
        async with serve_impl(impl, scheme=scheme) as dut:
            for _ in range(3):
                peer = await raw_peer(dut)
                await peer.send_raw(b"\xc1 not msgpack")
                for _ in range(100):
                    await peer.send_raw(b"\x93\xa4PING\x01\x80" + b"\x00" * 2000)
                assert error_code(await peer.recv()) == 400
                assert await peer.recv() is None
    run(main())


@pytest.mark.parametrize("op", ["LIST", "READ", "DEFINE", "WRITE", "INVOKE", "STREAM_START", "STATS"])
@impls
def test_nothing_is_readable_before_authentication(impl: str, op: str) -> None:
    async def main() -> None:
        async with serve_impl(impl) as dut:
            peer = await raw_peer(dut)
            reply = await peer.request("HELLO", {"version": "1.0"})
            assert reply[0] == "OK" and reply[2]["auth"] == "hmac-sha256"
            args = {"msg": 1, "names": ["counter"], "rate_hz": 1.0, "values": [1], "name": "math.add"}
            reply = await peer.request(op, args)
            assert error_code(reply) == 409 and "before AUTH" in reply[2]["message"]
            assert await peer.recv() is None  # a protocol error closes an unauthenticated peer
    run(main())


@impls
def test_commands_before_hello_are_refused_with_a_state_error(impl: str) -> None:
    async def main() -> None:
        async with serve_impl(impl) as dut:
            peer = await raw_peer(dut)
            reply = await peer.request("AUTH", {"cnonce": b"x" * 16, "mac": b"y" * 32})
            assert error_code(reply) == 409 and "HELLO" in reply[2]["message"]
    run(main())


@impls
def test_an_incompatible_major_version_is_refused(impl: str) -> None:
    async def main() -> None:
        async with serve_impl(impl) as dut:
            peer = await raw_peer(dut)
            reply = await peer.request("HELLO", {"version": "2.0"})
            assert error_code(reply) == IncompatibleVersion.code
            assert "1.0" in reply[2]["message"]
            assert await peer.recv() is None
    run(main())


@impls
def test_an_authenticated_peer_gets_errors_and_is_cut_off_only_after_many(impl: str) -> None:
    async def main() -> None:
        async with serve_impl(impl) as dut:
            peer = await raw_peer(dut)
            assert (await peer.login())[0] == "OK"
            reply = await peer.request("READ", {"msg": "one"})
            assert error_code(reply) == 400 and "'msg'" in reply[2]["message"]
            assert error_code(await peer.request("NOPE")) == 400
            assert (await peer.request("PING"))[0] == "OK"
            for _ in range(MAX_PROTOCOL_ERRORS - 2):
                await peer.send_raw(b"\xc1")
                assert error_code(await peer.recv()) == 400
            assert await peer.recv() is None
    run(main())


@impls
def test_deep_nesting_and_long_arrays_are_refused(impl: str) -> None:
    async def main() -> None:
        async with serve_impl(impl, max_depth=8, max_array_len=100) as dut:
            peer = await raw_peer(dut)
            await peer.login()
            nested: list = []
            for _ in range(20):
                nested = [nested]
            await peer.send(["INVOKE", 9, {"name": "math.sum", "args": nested}])
            assert error_code(await peer.recv()) == 413
            peer = await raw_peer(dut)
            await peer.login()
            await peer.send(["INVOKE", 9, {"name": "math.sum", "args": [list(range(500))]}])
            assert error_code(await peer.recv()) == 413
    run(main())


@impls
def test_unauthenticated_connections_time_out_with_a_reason(impl: str) -> None:
    async def main() -> None:
        # long enough for a client to authenticate even on a starved host
        async with serve_impl(impl, auth_timeout_s=1.0) as dut:
            peer = await raw_peer(dut)
            await peer.request("HELLO", {"version": "1.0"})
            frame = await peer.recv(timeout_s=10.0)
            assert error_code(frame) == 408 and "authenticated" in frame[2]["message"]
            assert await peer.recv() is None
            async with await dut.client() as client:  # authenticated in time
                await asyncio.sleep(1.1)
                # the Python device here is not ticking; the C device always is
                assert (await client.ping())["tick"] >= (-1 if impl == "python" else 0)
    run(main())


@impls
def test_clients_beyond_the_maximum_are_refused_with_a_clear_error(impl: str) -> None:
    async def main() -> None:
        async with serve_impl(impl, max_clients=2) as dut:
            first = await dut.client()
            second = await dut.client()
            with pytest.raises(TooMany, match="at most 2"):
                await dut.client()
            assert (await first.stats())["clients"] == 2
            await second.close()
            while (await first.stats())["clients"] > 1:  # the device has seen it go
                await asyncio.sleep(0.02)
            third = await dut.client()
            assert third.connected
            await first.close()
            await third.close()
    run(main())


@impls
def test_register_and_stream_limits_answer_with_errors(impl: str) -> None:
    async def main() -> None:
        async with serve_impl(impl, max_messages=2, max_names_per_message=3,
                              max_streams_per_client=1) as dut:
            client = await dut.client()
            await client.define(["counter"])
            await client.stream(["wave.sine"], rate_hz=10)
            with pytest.raises(TooMany, match="messages"):
                await client.define(["wave.cosine"])
            with pytest.raises(ValueError, match="at most 3"):
                await client.define(["counter", "wave.sine", "wave.cosine", "pair.a"])
            with pytest.raises(TooMany, match="streams"):
                await client.stream(["counter"], rate_hz=10)
            await client.close()
    run(main())


@pytest.mark.parametrize("impl", ["python", "c"])
def test_oversized_tcp_frames_close_only_that_connection(impl: str) -> None:
    async def main() -> None:
        async with serve_impl(impl, scheme="tcp", max_frame_bytes=4096) as dut:
            url = dut.url
            good = await Client.connect(url, password=PASSWORDS["observer"])
            host, port = url.removeprefix("tcp://").split(":")
            reader, writer = await asyncio.open_connection(host, int(port))
            writer.write(struct.pack(">I", 10_000_000) + b"x" * 100)
            size = struct.unpack(">I", await reader.readexactly(4))[0]
            frame = msgpack.unpackb(await reader.readexactly(size))
            assert frame[0] == "ERR" and frame[2]["code"] == 413
            assert await reader.read() == b""  # closed by the endpoint
            writer.close()
            assert "counter" in await good.read(["counter"])
            await good.close()
    run(main())


@pytest.mark.parametrize("impl", ["python", "c-relay"])
def test_text_websocket_messages_close_the_connection_with_a_reason(impl: str) -> None:
    async def main() -> None:
        from websockets.asyncio.client import connect

        async with serve_impl(impl, scheme="ws") as dut:
            url = dut.url
            ws = await connect(url, proxy=None)
            await ws.send("HELLO")
            frame = msgpack.unpackb(await ws.recv())
            assert frame[0] == "ERR" and "binary" in frame[2]["message"]
            await ws.wait_closed()
            assert ws.close_code == 1008
    run(main())
