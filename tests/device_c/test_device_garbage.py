"""10^5 garbage frames at the C device (sanitizer build, TCP) while a client streams.

The garbage is drawn from a seeded generator: random bytes, real requests with flipped,
dropped or inserted bytes, truncated requests, random msgpack values, and well-formed
[OP, seq, args] frames whose fields have the wrong types or hostile values. Eight peers
log in and send frames until the device cuts them off (8 protocol errors, §7), then come
back, until the device has answered 10^5 of them. Meanwhile a victim streams two signals
at every tick. The device must answer each frame it reads with one reply (never
`internal`), and when it cuts a peer off its last reply must say why; it must lose no
sample of the victim's stream, and exit cleanly with no sanitizer report and no leak.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import random
import socket
import struct
import threading

import msgpack
import numpy as np
from astcom_helpers import PASSWORDS
from device_impls import DeviceProcess, device_args

from astcom_client import Client
from astcom_client.auth import client_mac
from astcom_client.throttle import ThrottlePolicy

N_FRAMES = 100_000
N_PEERS = 8
FRAMES_PER_BURST = 12  # more than the 8 protocol errors that cut a peer off
LOOP_RATE_HZ = 1000.0
DATA_PREFIX = b"\x99\xa4DATA"  # a DATA frame: an array of 9 starting with the str DATA

# real requests, the raw material of the mutations
REQUESTS = [
    ["PING", 7, {}],
    ["LIST", 8, {"prefix": "wave."}],
    ["DEFINE", 9, {"names": ["counter", "wave.sine"]}],
    ["READ", 10, {"msg": 1}],
    ["WRITE", 11, {"msg": 1, "values": [1.5, 2]}],
    ["INVOKE", 12, {"name": "math.add", "args": [1.0, 2.0]}],
    ["INVOKE", 13, {"name": "math.sum", "args": [[1.0, 2.0, 3.0]]}],
    ["STREAM_START", 14, {"msg": 1, "rate_hz": 10.0}],
    ["STREAM_STOP", 15, {"msg": 1}],
    ["STATS", 16, {}],
    ["UNDEFINE", 17, {"msg": 1}],
]
HOSTILE_VALUES = [None, True, -1, 2**63, 2**64 - 1, -(2**63), 1e308, float("nan"),
                  float("inf"), "", "x" * 300, "é\u0000", b"", b"\xff" * 40, [], [[[]]], {},
                  {"": None}, msgpack.ExtType(1, b"\x00"), msgpack.ExtType(2, b"\xff" * 3),
                  msgpack.ExtType(99, b"")]


def random_value(rng: random.Random, depth: int = 0):
    kind = rng.randrange(8 if depth < 4 else 5)
    if kind == 0:
        return rng.choice(HOSTILE_VALUES)
    if kind == 1:
        return rng.randint(-(2**63), 2**64 - 1)
    if kind == 2:
        return rng.uniform(-1e6, 1e6)
    if kind == 3:
        return "".join(rng.choice("abcdefghijklmnopqrstuvwxyz._") for _ in range(rng.randrange(12)))
    if kind == 4:
        return rng.randbytes(rng.randrange(20))
    if kind == 5:
        return [random_value(rng, depth + 1) for _ in range(rng.randrange(5))]
    if kind == 6:
        keys = [None, True, -5, 2**64 - 1, 0.5, b"k", "msg", "names", "values", ""]
        return {rng.choice(keys) if rng.random() < 0.3 else str(rng.randrange(99)):
                random_value(rng, depth + 1) for _ in range(rng.randrange(4))}
    return msgpack.ExtType(rng.randrange(128), rng.randbytes(rng.randrange(12)))


def pack(obj) -> bytes:
    return msgpack.packb(obj, use_bin_type=True)


def garbage_frame(rng: random.Random) -> bytes:
    """One frame of garbage (see the module docstring)."""
    kind = rng.randrange(6)
    base = bytearray(pack(rng.choice(REQUESTS)))
    if kind == 0:
        return rng.randbytes(rng.randrange(1, 200))
    if kind == 1:  # flipped bytes
        for _ in range(rng.randrange(1, 4)):
            base[rng.randrange(len(base))] = rng.randrange(256)
        return bytes(base)
    if kind == 2:  # truncated, or a byte dropped or inserted
        cut = rng.randrange(1, len(base))
        choice = rng.randrange(3)
        if choice == 0:
            return bytes(base[:cut])
        if choice == 1:
            return bytes(base[:cut] + base[cut + 1:])
        return bytes(base[:cut] + bytes([rng.randrange(256)]) + base[cut:])
    if kind == 3:
        return pack(random_value(rng))
    if kind == 4:  # the right shape, the wrong contents
        op = rng.choice(REQUESTS)[0] if rng.random() < 0.8 else random_value(rng, 3)
        args = {str(k): random_value(rng, 2) for k in rng.sample(
            ["msg", "names", "values", "name", "args", "rate_hz", "prefix", "version", "x"],
            rng.randrange(4))}
        return pack([op, rng.choice([0, 1, 2**63 - 1, 2**63, -1, "1", None]), args])
    # extra trailing bytes, or two values in one frame
    return bytes(base) + rng.randbytes(rng.randrange(1, 8))


def flood(host: str, port: int, seed: int, counts: dict[str, int], stop: threading.Event,
          lock: threading.Lock) -> None:
    """Log in, send a burst of garbage, read every reply until the device closes; repeat.

    Plain blocking sockets in a thread: the flood costs the test process far less than
    asyncio would, so the device, not the flooder, sets the pace."""
    rng = random.Random(seed)
    while not stop.is_set():
        with socket.create_connection((host, port), timeout=20) as sock, \
                sock.makefile("rb") as incoming:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            sock.sendall(framed(pack(["HELLO", 1, {"version": "1.0", "client": "flood"}])))
            nonce = msgpack.unpackb(read_frame(incoming))[2]["nonce"]
            cnonce = os.urandom(16)
            mac = client_mac(PASSWORDS["operator"], nonce, cnonce)
            sock.sendall(framed(pack(["AUTH", 2, {"cnonce": cnonce, "mac": mac}])))
            assert msgpack.unpackb(read_frame(incoming))[0] == "OK"
            burst = b"".join(framed(garbage_frame(rng)) for _ in range(FRAMES_PER_BURST))
            with contextlib.suppress(ConnectionError):  # it may cut us off while we write
                sock.sendall(burst)
            replies = []
            while (data := read_frame(incoming)) is not None:
                if data.startswith(DATA_PREFIX):  # a garbage STREAM_START may have started one
                    continue
                replies.append(msgpack.unpackb(data, raw=False, strict_map_key=False))
        for reply in replies:
            if reply[0] == "ERR":  # never `internal`: 500 only from device.fail
                assert reply[2]["code"] != 500 or "failed" in reply[2]["message"], reply
        # cut off before the burst's end: the last reply says why (8 protocol errors, an
        # oversized value, or the OK of a BYE among the garbage)
        if len(replies) < FRAMES_PER_BURST:
            protocol_errors = sum(r[0] == "ERR" and r[2]["code"] in (400, 409) for r in replies)
            last = replies[-1]
            assert (protocol_errors == 8 and last[2]["code"] in (400, 409)) or last[0] == "OK" \
                or last[2]["code"] == 413, replies
        with lock:
            counts["replies"] += len(replies)
            counts["errors"] += sum(r[0] == "ERR" for r in replies)
            if counts["replies"] >= N_FRAMES:
                stop.set()


def framed(frame: bytes) -> bytes:
    return struct.pack(">I", len(frame)) + frame


def read_frame(incoming) -> bytes | None:
    """The next length-prefixed frame, or None at the end of the connection."""
    try:
        head = incoming.read(4)
        if len(head) < 4:
            return None
        return incoming.read(struct.unpack(">I", head)[0])
    except ConnectionError:
        return None


async def victim(url: str, ready: asyncio.Event, stop: threading.Event) -> dict:
    """Stream counter and wave.sine at every tick until `stop`; return what arrived."""
    out = {"ticks": [], "counter": [], "lost": 0, "seqs": []}
    async with await Client.connect(url, password=PASSWORDS["observer"]) as client:
        stream = await client.stream(["counter", "wave.sine"], rate_hz=LOOP_RATE_HZ)
        ready.set()
        async for packet in stream:
            out["ticks"].extend((packet.first_tick + np.arange(packet.n)).tolist())
            out["counter"].extend(packet.column("counter").tolist())
            out["lost"] += packet.lost
            out["seqs"].append(packet.seq)
            if stop.is_set() and len(out["seqs"]) > 1:
                break
        await stream.stop()
        out["stats"] = await client.stats()
    return out


def test_garbage_frames_are_each_answered_and_a_streaming_client_loses_nothing(asan_device,
                                                                                 tmp_path):
    stats_path = tmp_path / "device-stats.json"
    # The flooders log in with the right password hundreds of times a second; the password
    # throttle's overall limit (§10: 5 checks/s) would rightly refuse most of them, and this
    # test is about garbage after a login, not about logins (tests/astcom/
    # test_astcom_auth_throttle.py is): the overall limit is opened wide here.
    logins = ThrottlePolicy(global_rate_per_s=100_000.0, global_burst=100_000)
    proc = DeviceProcess(["--tcp", "127.0.0.1:0", "--stats", str(stats_path),
                          *device_args(loop_rate_hz=LOOP_RATE_HZ, throttle=logins)])
    try:
        url = proc.wait_line(r"(tcp://\S+)")[1]
        host, port = url.removeprefix("tcp://").rsplit(":", 1)

        async def main():
            counts = {"replies": 0, "errors": 0}
            ready, done, lock = asyncio.Event(), threading.Event(), threading.Lock()
            watched = asyncio.create_task(victim(url, ready, done))
            await ready.wait()
            await asyncio.gather(*(asyncio.to_thread(flood, host, int(port), seed, counts, done,
                                                     lock) for seed in range(N_PEERS)))
            return counts, await asyncio.wait_for(watched, 60)

        counts, seen = asyncio.run(asyncio.wait_for(main(), 600))
    finally:
        proc.stop()  # fails on a crash, a sanitizer report or a leak
    assert counts["replies"] >= N_FRAMES
    assert counts["errors"] > 0.9 * counts["replies"]  # garbage indeed
    # the victim: no seq gap, nothing dropped on either side, every tick in order; a
    # device starved of CPU for over 100 ms gives ticks up (they never existed, and the
    # tick numbers jump): such gaps may only add up to what it says it skipped
    device_stats = json.loads(stats_path.read_text())
    assert np.all(np.diff(seen["seqs"]) == 1)
    assert seen["lost"] == 0 and seen["stats"]["dropped_samples"] == 0
    assert device_stats["ring_lost_samples"] == 0 and device_stats["dropped_samples"] == 0
    ticks = np.asarray(seen["ticks"])
    steps = np.diff(ticks)
    assert len(ticks) > 100 and np.all(steps >= 1)
    assert np.sum(steps - 1) <= device_stats["skipped_ticks"]
    counter = np.asarray(seen["counter"])
    assert np.all(counter == ticks)  # the values of those ticks, not stale ones
