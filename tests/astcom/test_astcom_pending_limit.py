"""Connections that have not authenticated have their own limit and never lock clients out.

Against every device implementation (tests/astcom/device_impls.py).
"""

import asyncio

import pytest
from astcom_helpers import RawPeer, run, settle
from device_impls import ALL_IMPLS, serve_impl

from astcom_client import TooMany


async def let_it_see(dut) -> None:
    """Give the device time to notice a connection or a close."""
    if dut.impl == "python":
        await settle()
    else:
        await asyncio.sleep(0.05)


async def idle_peer(dut) -> RawPeer:
    """Return a peer that connected and says nothing (it waits for auth_timeout_s)."""
    peer = RawPeer(await dut.connect())
    await let_it_see(dut)
    return peer


impls = pytest.mark.parametrize("impl", ALL_IMPLS)


@impls
def test_peers_waiting_to_authenticate_do_not_take_the_slots_of_clients(impl: str) -> None:
    async def main() -> None:
        async with serve_impl(impl, max_clients=2, max_pending=2) as dut:
            await idle_peer(dut)
            first = await dut.client()
            second = await dut.client()  # 1 idle peer + 2 clients: all admitted
            stats = await first.stats()
            assert stats["clients"] == 3 and stats["pending"] == 1
            assert await second.invoke("math.add", 1.0, 2.0) == 3.0
            await first.close()
            await second.close()
    run(main())


@impls
def test_peers_beyond_the_pending_limit_are_refused_with_a_clear_error(impl: str) -> None:
    async def main() -> None:
        # the idle peers' auth timeout must outlast the next steps even on a starved host (at
        # 1 s it did not, beside a loaded suite: the refused peer's error came later than that)
        async with serve_impl(impl, max_clients=4, max_pending=2, auth_timeout_s=4.0) as dut:
            client = await dut.client()
            idle = [await idle_peer(dut), await idle_peer(dut)]
            refused = RawPeer(await dut.connect())
            frame = await refused.recv()
            assert frame[0] == "ERR" and frame[1] is None and frame[2]["code"] == TooMany.code
            assert "waiting to authenticate" in frame[2]["message"]
            assert "at most 2" in frame[2]["message"]
            assert await refused.recv() is None
            with pytest.raises(TooMany, match="waiting to authenticate"):
                await dut.client()
            assert "counter" in await client.read(["counter"])  # the authenticated one is unaffected
            # once the idle peers time out (each is told so), their pending slots are free again
            for peer in idle:
                frame = await peer.recv(timeout_s=30.0)
                assert frame[0] == "ERR" and frame[2]["code"] == 408
            again = await dut.client()
            assert (await again.stats())["pending"] == 0
            await again.close()
            await client.close()
    run(main())


@impls
def test_authenticating_beyond_max_clients_is_refused_at_auth(impl: str) -> None:
    async def main() -> None:
        async with serve_impl(impl, max_clients=1) as dut:
            a, b = RawPeer(await dut.connect()), RawPeer(await dut.connect())
            # both wait to authenticate: neither holds a client's slot yet
            nonce_a = (await a.request("HELLO", {"version": "1.0"}))[2]["nonce"]
            nonce_b = (await b.request("HELLO", {"version": "1.0"}))[2]["nonce"]
            assert (await a.auth(nonce_a))[0] == "OK"
            reply = await b.auth(nonce_b)
            assert reply[0] == "ERR" and reply[1] == b.seq and reply[2]["code"] == TooMany.code
            assert "at most 1" in reply[2]["message"]
            assert await b.recv() is None
            assert (await a.request("PING"))[0] == "OK"
    run(main())


@impls
def test_without_authentication_hello_admits_at_most_max_clients(impl: str) -> None:
    async def main() -> None:
        async with serve_impl(impl, max_clients=1, passwords=None) as dut:
            a, b = RawPeer(await dut.connect()), RawPeer(await dut.connect())
            assert (await a.request("HELLO", {"version": "1.0"}))[2]["role"] == "operator"
            reply = await b.request("HELLO", {"version": "1.0"})
            assert reply[0] == "ERR" and reply[2]["code"] == TooMany.code
            assert await b.recv() is None
    run(main())



@impls
def test_a_peer_gets_a_few_small_frames_before_authenticating(impl: str) -> None:
    """§8: before AUTH at most max_pending_frames frames, each of max_pending_frame_bytes."""
    async def main() -> None:
        async with serve_impl(impl, scheme="tcp" if impl == "python" else None) as dut:
            chatty = RawPeer(await dut.connect())
            hello = await chatty.request("HELLO", {"version": "1.0"})
            limits = hello[2]["limits"]
            assert limits["max_pending_frames"] == 16 and limits["max_pending_frame_bytes"] == 4096
            for _ in range(15):  # 16 frames in all are answered
                assert (await chatty.request("PING"))[0] == "OK"
            frame = await chatty.request("PING")
            assert frame[0] == "ERR" and frame[1] is None and frame[2]["code"] == TooMany.code
            assert "16 frames before authenticating" in frame[2]["message"]
            assert await chatty.recv() is None
            big = RawPeer(await dut.connect())
            await big.send(["HELLO", 1, {"version": "1.0", "client": "x" * 5000}])
            frame = await big.recv()
            assert frame[0] == "ERR" and frame[2]["code"] in (413, 400)
            assert await big.recv() is None
            async with await dut.client() as client:  # after AUTH the full limits apply
                assert await client.invoke("math.sum", [1.0] * 1000) == 1000.0
    run(main())
