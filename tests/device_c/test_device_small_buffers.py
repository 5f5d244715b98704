"""A C device built with the firmware's small buffers (a 1 KiB reply scratch, 2 KiB frames)
still answers a whole LIST (it goes out in parts: over TCP with its length first, over the
framed link as one COBS frame encoded as it is written) and streams without loss.
The sanitizer build, directly over TCP and through the Relay over a pty pair."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest
from astcom_helpers import PASSWORDS
from device_impls import DeviceProcess, device_args, relayed_device

from astcom_client import Client

SMALL = ["--max-reply-bytes", "1024", "--max-frame-bytes", "2048"]
NAMES = [f"extra.s{i:02d}" for i in range(16)]
RATE_HZ = 200.0


async def session(url: str) -> dict:
    async with await Client.connect(url, password=PASSWORDS["observer"]) as client:
        entries = await client.list()
        # 200 Hz: small packets (what 1 KiB holds), and the Relay's queue of 256 of them per
        # client holds seconds of them while a loaded host keeps this client from reading
        stream = await client.stream(NAMES, rate_hz=RATE_HZ)
        packets = []
        async for packet in stream:
            packets.append(packet)
            if len(packets) == 20:
                break
        await stream.stop()
        return {"entries": entries, "packets": packets, "stats": await client.stats()}


async def reference_list() -> list:
    """The LIST of the same device with the default (256 KiB) scratch, in one frame."""
    proc = DeviceProcess(["--tcp", "127.0.0.1:0", *device_args(n_extra_signals=16)])
    try:
        url = proc.wait_line(r"(tcp://\S+)")[1]
        async with await Client.connect(url, password=PASSWORDS["observer"]) as client:
            return await client.list()
    finally:
        await asyncio.to_thread(proc.stop)


async def over_tcp() -> dict:
    proc = DeviceProcess(["--tcp", "127.0.0.1:0", *SMALL, *device_args(n_extra_signals=16)])
    try:
        return await session(proc.wait_line(r"(tcp://\S+)")[1])
    finally:
        await asyncio.to_thread(proc.stop)


async def over_the_link() -> dict:
    async with relayed_device([*SMALL, *device_args(n_extra_signals=16)]) as url:
        return await session(url)


@pytest.mark.parametrize("transport", ["tcp", "relay"])
def test_a_small_device_sends_a_whole_list_and_streams(asan_device, transport):
    async def main():
        got = await (over_tcp() if transport == "tcp" else over_the_link())
        return got, await reference_list()

    got, reference = asyncio.run(asyncio.wait_for(main(), 120))
    entries = [(e.name, e.type, e.kind, e.unit, e.doc) for e in got["entries"]]
    assert entries == [(e.name, e.type, e.kind, e.unit, e.doc) for e in reference]
    assert len(entries) > 70  # far more than 1 KiB of LIST
    packets = got["packets"]
    # small packets (what fits 1 KiB), every 5th tick, nothing lost
    assert max(p.n for p in packets) * 16 * 8 < 1024
    ticks = np.concatenate([p.first_tick + p.period_ticks * np.arange(p.n) for p in packets])
    assert np.all(np.diff(ticks) == 5)
    assert sum(p.lost for p in packets) == 0 and got["stats"]["dropped_samples"] == 0
    values = np.concatenate([p.column("extra.s03") for p in packets])
    np.testing.assert_allclose(values, np.sin(2 * np.pi * 5.0 * ticks / 1000.0 + 3), atol=1e-12)
