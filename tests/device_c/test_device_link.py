"""The framed link's sessions are independent: a deferred call on one channel holds that
channel's later requests (as on a TCP connection) but not the other channels', nor the
link itself; a client that piles up more than the link can park behind its call is cut
off alone. The C device (sanitizer build) through the Relay over a pty pair."""

from __future__ import annotations

import asyncio

from astcom_helpers import PASSWORDS, RawPeer
from device_impls import WsRaw, device_args, relayed_device
from websockets.asyncio.client import connect

from astcom_client import Client
from astcom_client.codec import Codec

WAIT_S = 5.0  # device.wait's longest


async def scenario(url: str) -> dict:
    a = await Client.connect(url, password=PASSWORDS["operator"], timeout_s=30)
    b = await Client.connect(url, password=PASSWORDS["operator"], timeout_s=30)
    try:
        waiting = asyncio.create_task(a.invoke("device.wait", WAIT_S))
        ping_a = asyncio.create_task(a.ping())  # behind a's call on the same channel
        await asyncio.sleep(0.2)  # the call is on the device
        answers = [await b.ping() for _ in range(5)]
        answers.append(await b.invoke("math.add", 1.0, 2.0))
        return {"b_answers": answers, "a_done_after_b": waiting.done(),
                "a_ping_done_after_b": ping_a.done()}
    finally:
        await b.close()
        await a.close()  # the call is dropped with its channel


def test_a_deferred_call_holds_its_channel_only(asan_device):
    async def main():
        async with relayed_device(device_args()) as url:
            return await scenario(url)

    out = asyncio.run(asyncio.wait_for(main(), 120))
    assert out["b_answers"][-1] == 3.0 and len(out["b_answers"]) == 6
    # b was answered while a's call (5 s of device time) still ran, and a's own later
    # request still waited behind it
    assert not out["a_done_after_b"] and not out["a_ping_done_after_b"]


async def flood_behind_a_call(url: str) -> dict:
    """a calls device.wait, then sends more than the link can park for it; b keeps asking."""
    a = await connect(url, proxy=None, compression=None, max_size=None)
    b = await Client.connect(url, password=PASSWORDS["operator"], timeout_s=30)
    try:
        codec = Codec()
        peer = RawPeer(WsRaw(a))
        assert (await peer.login())[0] == "OK"
        await peer.send(["INVOKE", 10, {"name": "device.wait", "args": [WAIT_S]}])
        await asyncio.sleep(0.2)
        for seq in range(11, 16):  # 5 frames of 3 KiB; the park holds 2 of 4 KiB
            await a.send(codec.encode(["PING", seq, {"pad": b"x" * 3000}]))
        replies = []
        while (frame := await peer.recv(timeout_s=10)) is not None:
            replies.append(frame)
        return {"a": replies, "b": [await b.ping() for _ in range(3)]}
    finally:
        await b.close()
        await a.close()


def test_a_client_that_overflows_the_park_behind_its_call_is_cut_off_alone(asan_device):
    async def main():
        async with relayed_device(["--max-frame-bytes", "4096", *device_args()]) as url:
            return await flood_behind_a_call(url)

    out = asyncio.run(asyncio.wait_for(main(), 120))
    refusal = out["a"][-1]
    assert refusal[0] == "ERR" and refusal[1] is None and refusal[2]["code"] == 429
    assert "wait behind a call" in refusal[2]["message"]
    assert len(out["b"]) == 3  # the link and the other client go on
