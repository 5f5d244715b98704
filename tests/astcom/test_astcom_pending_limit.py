"""Connections that have not authenticated have their own limit and never lock clients out."""

import asyncio

import pytest
from astcom_helpers import RawPeer, memory_client, run, served, settle

from astcom_client import TooMany


async def idle_peer(endpoint) -> RawPeer:
    """Return a peer that connected and says nothing (it waits for auth_timeout_s)."""
    peer = RawPeer(endpoint.connect_in_memory())
    await settle()
    return peer


def test_peers_waiting_to_authenticate_do_not_take_the_slots_of_clients() -> None:
    async def main() -> None:
        async with served(max_clients=2, max_pending=2) as (_, endpoint, _):
            await idle_peer(endpoint)
            first = await memory_client(endpoint)
            second = await memory_client(endpoint)  # 1 idle peer + 2 clients: all admitted
            stats = await first.stats()
            assert stats["clients"] == 3 and stats["pending"] == 1
            assert await second.invoke("math.add", 1.0, 2.0) == 3.0
            await first.close()
            await second.close()
    run(main())


def test_peers_beyond_the_pending_limit_are_refused_with_a_clear_error() -> None:
    async def main() -> None:
        async with served(max_clients=4, max_pending=2, auth_timeout_s=0.3) as (_, endpoint, _):
            client = await memory_client(endpoint)
            await idle_peer(endpoint)
            await idle_peer(endpoint)
            refused = RawPeer(endpoint.connect_in_memory())
            frame = await refused.recv()
            assert frame[0] == "ERR" and frame[1] is None and frame[2]["code"] == TooMany.code
            assert "waiting to authenticate" in frame[2]["message"]
            assert "at most 2" in frame[2]["message"]
            assert await refused.recv() is None
            with pytest.raises(TooMany, match="waiting to authenticate"):
                await memory_client(endpoint)
            assert "counter" in await client.read(["counter"])  # the authenticated one is unaffected
            # once the idle peers time out, their pending slots are free again
            await asyncio.sleep(0.5)
            again = await memory_client(endpoint)
            assert (await again.stats())["pending"] == 0
            await again.close()
            await client.close()
    run(main())


def test_authenticating_beyond_max_clients_is_refused_at_auth() -> None:
    async def main() -> None:
        async with served(max_clients=1) as (_, endpoint, _):
            a, b = RawPeer(endpoint.connect_in_memory()), RawPeer(endpoint.connect_in_memory())
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


def test_without_authentication_hello_admits_at_most_max_clients() -> None:
    async def main() -> None:
        async with served(max_clients=1, passwords=None) as (_, endpoint, _):
            a, b = RawPeer(endpoint.connect_in_memory()), RawPeer(endpoint.connect_in_memory())
            assert (await a.request("HELLO", {"version": "1.0"}))[2]["role"] == "operator"
            reply = await b.request("HELLO", {"version": "1.0"})
            assert reply[0] == "ERR" and reply[2]["code"] == TooMany.code
            assert await b.recv() is None
    run(main())

