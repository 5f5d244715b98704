"""A stream's first DATA packet never reaches the client before its STREAM_START reply."""

import asyncio

import msgpack
from astcom_helpers import RawPeer, run, served, settle

from astcom_client.transports import MemoryTransport, memory_pair


class SlowReplySocket:
    """The endpoint's end of a connection whose send of one reply blocks until released.

    Models a socket that is full (back-pressure) just while the endpoint sends the
    STREAM_START reply; everything else passes straight through.
    """

    def __init__(self, inner: MemoryTransport, held_seq: int) -> None:
        self.inner, self.held_seq, self.peer = inner, held_seq, inner.peer
        self.holding, self.release = asyncio.Event(), asyncio.Event()

    async def send(self, frame: bytes) -> None:
        head = msgpack.unpackb(frame, ext_hook=lambda code, data: None, strict_map_key=False)
        if head[0] == "OK" and head[1] == self.held_seq:
            self.holding.set()
            await self.release.wait()
        await self.inner.send(frame)

    async def recv(self) -> bytes | None:
        return await self.inner.recv()

    async def close(self, code: int = 1000, reason: str = "") -> None:
        await self.inner.close(code, reason)


def test_data_of_a_new_stream_waits_for_its_stream_start_reply() -> None:
    async def main() -> None:
        async with served() as (_, endpoint, _):
            client_end, server_end = memory_pair(1024)
            socket = SlowReplySocket(server_end, held_seq=10)
            session = asyncio.create_task(endpoint.handle_connection(socket))
            peer = RawPeer(client_end)
            await peer.login()
            msg = (await peer.request("DEFINE", {"names": ["counter"]}))[2]["msg"]
            await peer.send(["STREAM_START", 10, {"msg": msg, "rate_hz": 1000}])
            await asyncio.wait_for(socket.holding.wait(), 2.0)
            endpoint.publish(0, 1_763_769_600_000_000, 200)  # 10 packets due while the reply hangs
            await settle(20)
            socket.release.set()
            kinds = []
            while "OK" not in kinds or kinds.count("DATA") < 3:
                frame = await peer.recv()
                kinds.append(frame[0])
            assert kinds[0] == "OK", kinds
            await peer.request("BYE")
            await asyncio.wait_for(session, 2.0)
    run(main())
