"""Password attempts are throttled per address and overall (docs/astcom-protocol.md §10), on
every device implementation: the Python endpoint, the C device over TCP, and the C device
behind the Relay (which tells the device each client's address in the link's OPEN).

The guessers connect from distinct loopback addresses (127.0.0.k) and speak the protocol
by hand: HELLO, then AUTH with a MAC computed from the spec (§5), right or wrong. The
numbers asserted are the spec's (0.25 s doubling, a hold of at most 5 s) or those of a
policy the test sets (a lockout after 3 failures, an overall rate it can outrun), since
the spec's 20 failures would take minutes; the device's own clock decides, and a slower
host only makes the waits the device computes shorter, never the counts different.
"""

from __future__ import annotations

import asyncio
import hashlib
import hmac
import os
import re
import struct
from typing import Any

import msgpack
import pytest
from astcom_helpers import PASSWORDS
from device_impls import ALL_IMPLS, serve_impl

from astcom_client.throttle import ThrottlePolicy

# the spec's defaults (§10): what the devices run with unless told otherwise
SPEC = ThrottlePolicy()
TIME_SCALE = 10  # see `spec_sped_up`


def spec_sped_up(k: float) -> ThrottlePolicy:
    """The spec's policy on a clock k times faster: every duration divided by k, the overall
    rate multiplied by k, the counts (burst, lockout failures, addresses) unchanged. A
    device that runs it gives the same verdicts, in the same order, to guesses k times
    quicker, as long as the guessers' round trips stay short beside the shortest delay
    (25 ms for k = 10; a slower guesser only meets shorter waits, never other codes)."""
    s = SPEC
    return ThrottlePolicy(first_delay_s=s.first_delay_s / k, max_delay_s=s.max_delay_s / k,
                          lockout_failures=s.lockout_failures, lockout_s=s.lockout_s / k,
                          forget_s=s.forget_s / k, global_rate_per_s=s.global_rate_per_s * k,
                          global_burst=s.global_burst, max_hold_s=s.max_hold_s / k,
                          max_addresses=s.max_addresses)
CLIENT_LABEL = b"ASTCom-1 client\x00"  # §5: 15 ASCII bytes and a zero byte
WRONG_PASSWORD_RE = re.compile(r"auth: wrong password from (\S+) \((\d+) in a row")


def scheme_of(impl: str) -> str:
    return "tcp" if impl == "c" else "ws"


class Peer:
    """One raw connection from a chosen source address (TCP length-prefixed or WebSocket)."""

    @classmethod
    async def open(cls, url: str, source: str) -> Peer:
        self = cls()
        if url.startswith("tcp://"):
            host, port = url.removeprefix("tcp://").rsplit(":", 1)
            self.reader, self.writer = await asyncio.open_connection(
                host, int(port), local_addr=(source, 0))
            self.ws = None
        else:
            from websockets.asyncio.client import connect

            self.ws = await connect(url, proxy=None, compression=None, max_size=None,
                                    local_addr=(source, 0))
        return self

    async def request(self, frame: list) -> list | None:
        data = msgpack.packb(frame)
        try:
            if self.ws is not None:
                await self.ws.send(data)
                return msgpack.unpackb(await self.ws.recv())
            self.writer.write(struct.pack(">I", len(data)) + data)
            await self.writer.drain()
            head = await self.reader.readexactly(4)
            return msgpack.unpackb(await self.reader.readexactly(struct.unpack(">I", head)[0]))
        except Exception:  # the device closed first (it answers before it closes)
            return None

    async def close(self) -> None:
        try:
            if self.ws is not None:
                await self.ws.close()
            else:
                self.writer.close()
        except Exception:
            pass


async def attempt(url: str, source: str, password: str | None = None) -> tuple[int, str]:
    """One connection from `source` with one AUTH (a random MAC when `password` is None);
    return the answer's code (200 for OK) and message."""
    peer = await Peer.open(url, source)
    try:
        hello = await peer.request(["HELLO", 1, {"version": "1.0", "client": "guesser"}])
        assert hello and hello[0] == "OK", hello
        cnonce = os.urandom(16)
        mac = (hmac.new(password.encode(), CLIENT_LABEL + hello[2]["nonce"] + cnonce,
                        hashlib.sha256).digest() if password is not None else os.urandom(32))
        reply = await peer.request(["AUTH", 2, {"cnonce": cnonce, "mac": mac, "role": None}])
        assert reply is not None, "the device closed without answering the AUTH"
        return (200, "") if reply[0] == "OK" else (reply[2]["code"], reply[2]["message"])
    finally:
        await peer.close()


class FailureLog:
    """The wrong passwords a device reported: the Python endpoint's on_auth_failure hook,
    the C device's log lines (its stderr, read once it has stopped)."""

    def __init__(self, dut: Any) -> None:
        self.dut = dut
        self.python: list[tuple[str, int]] = []
        if dut.endpoint is not None:
            dut.endpoint.on_auth_failure = lambda peer, f: self.python.append(
                (peer.rpartition(":")[0], f.failures))

    def entries(self) -> list[tuple[str, int]]:
        if self.dut.endpoint is not None:
            return self.python
        return [(m[1], int(m[2])) for m in WRONG_PASSWORD_RE.finditer(self.dut.log)]


def serve(impl: str, **config: Any):
    return serve_impl(impl, scheme=scheme_of(impl), **config)


def guessing_verdicts(policy: ThrottlePolicy, addresses: int, attempts: int, round_trip_s: float
                      ) -> list[tuple[str, bool, str, float]]:
    """The reference throttle's verdicts for `addresses` guessers, each sending `attempts`
    wrong passwords one after the other, a round trip apart (as the guessers below do):
    (address, refused, reason, wait_s) in the order the device would see them."""
    from astcom_client.throttle import AuthThrottle

    throttle = AuthThrottle(policy)
    arrivals = [(0.0, f"127.0.0.{k}", 0) for k in range(2, 2 + addresses)]
    out = []
    while arrivals:
        arrivals.sort()
        now_s, address, n = arrivals.pop(0)
        verdict = throttle.reserve(address, now_s)
        out.append((address, verdict.refused, verdict.reason, verdict.wait_s))
        done_s = now_s if verdict.refused else now_s + verdict.wait_s
        if not verdict.refused:
            throttle.failed(address, done_s)
        if n + 1 < attempts:
            arrivals.append((done_s + round_trip_s, address, n + 1))
    return out


def test_the_spec_sped_up_gives_the_spec_verdicts_in_the_same_order():
    """What lets the next test run the spec's policy ten times faster: the reference throttle
    gives the same verdicts to the same guesses on a clock ten times faster, the waits
    divided by ten, with round trips from none to a tenth of the shortest delay."""
    for round_trip_s in (0.0, 0.001, 0.01, 0.025):
        spec = guessing_verdicts(SPEC, 6, 12, round_trip_s)
        fast = guessing_verdicts(spec_sped_up(TIME_SCALE), 6, 12, round_trip_s / TIME_SCALE)
        assert [v[:3] for v in fast] == [v[:3] for v in spec], round_trip_s
        assert [v[3] * TIME_SCALE for v in fast] == pytest.approx([v[3] for v in spec], abs=1e-9)
        assert any(v[1] for v in spec) and not all(v[1] for v in spec)  # both kinds met


@pytest.mark.parametrize("impl", ALL_IMPLS)
def test_guesses_from_many_addresses_are_throttled_per_address_and_each_failure_reported(impl):
    """The twin of tests/hostile/test_hostile_astcom.py's test, on every implementation.

    The spec's policy sped up ten times (`spec_sped_up`): what is proved here is that each
    address is throttled on its own and each failure reported once, in order, not the
    spec's delays, which the next test proves at their own pace on every implementation
    (at the spec's pace each guesser would wait 7.75 s for the same verdicts)."""
    sources = [f"127.0.0.{k}" for k in range(2, 8)]

    async def run() -> tuple[dict[str, list[tuple[int, str]]], int, FailureLog]:
        async with serve(impl, throttle=spec_sped_up(TIME_SCALE)) as dut:
            log = FailureLog(dut)

            async def guesser(source: str) -> list[tuple[int, str]]:
                return [await attempt(dut.url, source) for _ in range(12)]

            codes = dict(zip(sources, await asyncio.gather(*map(guesser, sources)), strict=True))
            legit = (await attempt(dut.url, "127.0.0.20", PASSWORDS["operator"]))[0]
        return codes, legit, log

    results, legit, log = asyncio.run(asyncio.wait_for(run(), 240))
    codes = [c for cs in results.values() for c, _ in cs]
    assert set(codes) <= {401, 429}, codes
    assert codes.count(429) > 0  # refused unchecked
    reported = log.entries()
    assert codes.count(401) == len(reported)  # each wrong password reported, once
    assert {address for address, _ in reported} <= set(sources)
    for source, answers in results.items():  # reported in order, per address
        assert [n for a, n in reported if a == source] == list(
            range(1, 1 + [c for c, _ in answers].count(401)))
    assert legit == 200  # another address logs in all the same


@pytest.mark.parametrize("impl", ALL_IMPLS)
def test_one_address_is_held_by_the_spec_delays_then_refused_unchecked(impl):
    """Guesses one after the other from one address: the n-th failure puts 0.25 s × 2^(n-1)
    before the next check and a check is held at most 5 s, so the 1st to 6th are checked
    (waits 0, 0.25, 0.5, 1, 2, 4 s) and the 7th, which would wait 8 s, is refused."""
    # attempt k waits delay_s(k - 1) after the check before it
    expected_checked = max(k for k in range(1, 20) if SPEC.delay_s(k - 1) <= SPEC.max_hold_s)
    assert expected_checked == 6  # the spec's numbers, worked out by the reference policy

    async def run() -> tuple[list[tuple[int, str]], FailureLog]:
        async with serve(impl) as dut:
            log = FailureLog(dut)
            answers = [await attempt(dut.url, "127.0.0.9") for _ in range(expected_checked + 2)]
        return answers, log

    answers, log = asyncio.run(asyncio.wait_for(run(), 240))
    codes = [c for c, _ in answers]
    assert codes == [401] * expected_checked + [429, 429], answers
    refusal = answers[expected_checked][1]
    m = re.fullmatch(r"too many wrong passwords from 127\.0\.0\.9: not checked; "
                     r"try again in (\d+) s", refusal)
    assert m, refusal
    # the device would hold it 8 s (4 s doubled) less the moments since the 6th check
    assert SPEC.max_hold_s < int(m[1]) <= SPEC.delay_s(expected_checked) + 0.5
    assert log.entries() == [("127.0.0.9", n) for n in range(1, expected_checked + 1)]


@pytest.mark.parametrize("impl", ALL_IMPLS)
def test_an_address_is_locked_out_after_its_failures_and_the_lockout_expires(impl):
    policy = ThrottlePolicy(first_delay_s=0.01, max_delay_s=0.02, lockout_failures=3,
                            lockout_s=1.5, max_hold_s=1.0)

    async def run() -> dict[str, Any]:
        out: dict[str, Any] = {}
        async with serve(impl, throttle=policy) as dut:
            log = FailureLog(dut)
            out["guesses"] = [await attempt(dut.url, "127.0.0.11") for _ in range(3)]
            # locked: even the right password is refused unchecked
            out["locked"] = await attempt(dut.url, "127.0.0.11", PASSWORDS["operator"])
            out["other"] = await attempt(dut.url, "127.0.0.12", PASSWORDS["observer"])
            await asyncio.sleep(policy.lockout_s + 0.5)  # the device's clock runs at least as far
            out["after"] = await attempt(dut.url, "127.0.0.11", PASSWORDS["operator"])
        out["log"] = log.entries()
        return out

    out = asyncio.run(asyncio.wait_for(run(), 120))
    assert [c for c, _ in out["guesses"]] == [401, 401, 401]
    code, message = out["locked"]
    assert code == 429
    m = re.fullmatch(r"127\.0\.0\.11 is locked out after too many wrong passwords: not "
                     r"checked; try again in (\d+) s", message)
    assert m and int(m[1]) <= policy.lockout_s + 0.5, message
    assert out["other"][0] == 200
    assert out["after"][0] == 200
    assert out["log"] == [("127.0.0.11", 1), ("127.0.0.11", 2), ("127.0.0.11", 3)]


@pytest.mark.parametrize("impl", ALL_IMPLS)
def test_guesses_spread_over_addresses_are_bounded_overall(impl):
    """Over all addresses at most `global_rate_per_s` checks a second after a burst: with
    a burst of 2 and one check per 20 s, the third address in a row would wait ~20 s, more
    than the 5-s hold, so only two guesses are checked, whatever the addresses."""
    policy = ThrottlePolicy(global_rate_per_s=0.05, global_burst=2)

    async def run() -> tuple[list[tuple[int, str]], list]:
        async with serve(impl, throttle=policy) as dut:
            log = FailureLog(dut)
            answers = [await attempt(dut.url, f"127.0.1.{k}") for k in range(1, 7)]
        return answers, log.entries()

    answers, reported = asyncio.run(asyncio.wait_for(run(), 120))
    assert [c for c, _ in answers] == [401, 401, 429, 429, 429, 429], answers
    for _, message in answers[2:]:
        m = re.fullmatch(r"too many login attempts on this server: not checked; "
                         r"try again in (\d+) s", message)
        assert m and policy.max_hold_s < int(m[1]) <= 1 / policy.global_rate_per_s + 0.5, message
    assert reported == [("127.0.1.1", 1), ("127.0.1.2", 1)]
