"""STATS tells how many stream packets wait for a client that reads slowly: the C device's
TCP transport counts the packets in its send ring (STATS queue_depths and per_client)."""

from __future__ import annotations

import asyncio
import socket

from astcom_helpers import PASSWORDS, RawPeer
from device_impls import DeviceProcess, TcpRaw, device_args

from astcom_client import Client

NAMES = [f"extra.s{i:02d}" for i in range(16)]
LOOP_RATE_HZ = 10_000.0  # 1.3 MB/s: the kernel's socket buffers fill within seconds


async def slow_reader(url: str) -> tuple[RawPeer, socket.socket]:
    """A client with a tiny receive buffer that streams 16 signals at every tick."""
    host, port = url.removeprefix("tcp://").rsplit(":", 1)
    sock = socket.socket()
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    sock.connect((host, int(port)))
    sock.setblocking(False)
    peer = RawPeer(TcpRaw(*await asyncio.open_connection(sock=sock, limit=4096)))
    assert (await peer.login())[0] == "OK"
    msg = (await peer.request("DEFINE", {"names": NAMES}))[2]["msg"]
    assert (await peer.request("STREAM_START", {"msg": msg, "rate_hz": LOOP_RATE_HZ}))[0] == "OK"
    return peer, sock


async def scenario(url: str) -> tuple[dict, dict, int]:
    peer, sock = await slow_reader(url)
    async with await Client.connect(url, password=PASSWORDS["observer"]) as watcher:
        depth, deadline = 0, asyncio.get_running_loop().time() + 30
        while depth < 20:  # the slow client stops reading (its buffers fill)
            assert asyncio.get_running_loop().time() < deadline, "no queue built up"
            await asyncio.sleep(0.2)
            stats = await watcher.stats()
            slow = max(stats["per_client"], key=lambda c: c["queue_depth"])
            depth = slow["queue_depth"]
        full = stats
        for _ in range(400):  # it reads again (raw frames): the queue drains
            assert await asyncio.wait_for(peer.transport.recv(), 10) is not None
        drained = await watcher.stats()
    sock.close()
    return full, drained, slow["id"]


def test_stats_count_the_packets_waiting_for_a_slow_client(asan_device):
    proc = DeviceProcess(["--tcp", "127.0.0.1:0",
                          *device_args(loop_rate_hz=LOOP_RATE_HZ, n_extra_signals=16)])
    try:
        url = proc.wait_line(r"(tcp://\S+)")[1]
        full, drained, slow_id = asyncio.run(asyncio.wait_for(scenario(url), 120))
    finally:
        proc.stop()
    assert full["queue_depths"][str(slow_id)] >= 20
    others = [c for c in full["per_client"] if c["id"] != slow_id]
    assert all(c["queue_depth"] <= 1 for c in others)  # the watcher reads its replies
    slow_after = next(c for c in drained["per_client"] if c["id"] == slow_id)
    assert slow_after["queue_depth"] < full["queue_depths"][str(slow_id)]
