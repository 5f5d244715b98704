"""Every example in docs/astcom-protocol.md is what the code produces, read from the page itself.

The hex examples are extracted from the document and compared with the codec's bytes;
the exchange of §9 is parsed from the document and played against a real Endpoint,
every concrete value shown there checked against the reply.
"""

import json
import os
import re
from pathlib import Path

import numpy as np
import pytest
from astcom_helpers import RawPeer, run

from astcom_client import Collection, Endpoint, EndpointConfig, TimestampUs
from astcom_client.auth import client_mac
from astcom_client.codec import Codec, encode_ndarray
from astcom_client.framing import frame_bytes
from astcom_client.timing import round_half_up, sample_offsets_us

SPEC = (Path(__file__).resolve().parents[2] / "docs" / "astcom-protocol.md").read_text()
HEX = r"`((?:[0-9a-f]{2} )+[0-9a-f]{2})`"
CODEC = Codec()


def unhex(text: str) -> bytes:
    return bytes.fromhex(text.replace(" ", ""))


def section(number: str) -> str:
    start = SPEC.index(f"\n## {number}. ")
    end = SPEC.find("\n## ", start + 1)
    return SPEC[start:end if end > 0 else None]


def test_the_tcp_framing_example_is_the_codecs_frame_with_its_length_prefix() -> None:
    match = re.search(r"the request `(\[.*?\])` \(§4\) is the frame\s+" + HEX + r",\s+sent as\s+" + HEX,
                      section("1"))
    assert match, "the TCP example of §1 is missing"
    value, frame, framed = json.loads(match[1]), unhex(match[2]), unhex(match[3])
    assert CODEC.encode(value) == frame
    assert frame_bytes(frame) == framed


def test_the_array_example_is_the_codecs_ext1_payload() -> None:
    match = re.search(r"the `f64` array `(\[.*?\]\])` is the ext 1 payload\s+" + HEX +
                      r"\s+followed by the six doubles LE \((\d+) bytes\)", SPEC)
    assert match, "the ext 1 example of §2.1 is missing"
    array = np.array(json.loads(match[1]), dtype=np.float64)
    ext = encode_ndarray(array)
    header = unhex(match[2])
    assert ext.code == 1 and ext.data[:len(header)] == header
    assert ext.data[len(header):] == array.astype("<f8").tobytes() and int(match[3]) == array.nbytes


def test_the_timestamp_and_64_bit_examples_are_the_codecs_bytes() -> None:
    match = re.search(r"the time `(\d+)` µs \(([0-9T:.-]+) UTC\) is\s+" + HEX, SPEC)
    assert match, "the ext 2 example of §2.2 is missing"
    t_us = int(match[1])
    assert CODEC.encode(TimestampUs(t_us)) == unhex(match[3])
    assert np.datetime64(match[2], "us").astype(np.int64) == t_us  # the date given matches
    plain = re.search(r"the time `(\d+)` as a plain int is\s+" + HEX, SPEC)
    assert plain and CODEC.encode(int(plain[1])) == unhex(plain[2])


def test_the_hello_byte_example_is_the_codecs_frame() -> None:
    match = re.search(r"Byte example: `(\[.*?\])` encodes to\s+" + HEX, section("9"))
    assert match, "the byte example of §9 is missing"
    assert CODEC.encode(json.loads(match[1])) == unhex(match[2])


# -- §9, played against an endpoint --------------------------------------------------------
PLACEHOLDER = re.compile(r"<[^<>]*>|\{\.\.\.\}")


def exchange_lines() -> list[tuple[str, object]]:
    """Return [(\"C\" or \"S\", value)] of the §9 code block, placeholders kept as strings."""
    block = section("9").split("```")[1]
    lines: list[str] = []
    for raw in block.strip().splitlines():
        if raw.startswith(("C:", "S:")):
            lines.append(raw)
        else:
            lines[-1] += " " + raw.strip()
    out = []
    for line in lines:
        side, text = line[0], line[2:].split("   (")[0].strip()
        text = PLACEHOLDER.sub(lambda m: json.dumps(m[0]), text).replace("nil", "null")
        out.append((side, json.loads(text)))
    return out


def check(shown, got, where: str) -> None:
    """Assert `got` (a decoded frame part) matches what the document shows."""
    if isinstance(shown, str) and shown == "{...}":
        assert isinstance(got, dict), where
    elif isinstance(shown, str) and shown.startswith("<"):
        if m := re.fullmatch(r"<(\d+) bytes>", shown):
            assert isinstance(got, bytes) and len(got) == int(m[1]), where
        elif m := re.fullmatch(r"<ext 1: (\w+) \((\d+), (\d+)\)>", shown):
            assert got.dtype == np.dtype("<" + {"f64": "f8"}[m[1]]), where
            assert got.shape == (int(m[2]), int(m[3])), where
        elif shown.startswith("<ext 2"):
            assert isinstance(got, TimestampUs), where
        else:
            pytest.fail(f"{where}: unknown placeholder {shown}")
    elif isinstance(shown, list):
        assert isinstance(got, list) and len(got) == len(shown), (where, got)
        for i, (s, g) in enumerate(zip(shown, got, strict=True)):
            check(s, g, f"{where}[{i}]")
    elif isinstance(shown, dict):
        assert isinstance(got, dict) and set(got) == set(shown), (where, got)
        for key in shown:
            check(shown[key], got[key], f"{where}.{key}")
    else:
        assert type(got) is type(shown) and got == shown, (where, shown, got)


def test_every_integer_of_the_exchange_is_exact_in_a_double() -> None:
    def ints(value):
        if isinstance(value, list | tuple):
            for v in value:
                yield from ints(v)
        elif isinstance(value, dict):
            yield from ints(list(value.values()))
        elif isinstance(value, int) and not isinstance(value, bool):
            yield value

    assert all(abs(v) < 2**53 for _, value in exchange_lines() for v in ints(value))


def reply_to(lines: list[tuple[str, object]], op: str) -> dict:
    """Return the result shown for the first request `op` of the exchange."""
    seq = next(v[1] for side, v in lines if side == "C" and v[0] == op)
    return next(v[2] for side, v in lines if side == "S" and v[0] == "OK" and v[1] == seq)


def test_the_complete_exchange_of_section_9_is_what_an_endpoint_answers() -> None:
    lines = exchange_lines()
    hello = reply_to(lines, "HELLO")
    t0_us = int(re.search(r"mount time (\d+) µs\)", section("9"))[1])
    loop_rate_hz = hello["loop_rate_hz"]
    names = next(v[2]["names"] for side, v in lines if side == "C" and v[0] == "DEFINE")
    read_reply = reply_to(lines, "READ")
    password = "doc-secret"

    async def main() -> None:
        coll = Collection()
        positions = np.array(read_reply["values"], dtype=np.float64)
        for i, name in enumerate(names):
            coll.add_slot(name, positions, i, type="f64")
        endpoint = Endpoint(coll, EndpointConfig(loop_rate_hz=loop_rate_hz, name=hello["server"],
                                                 passwords={"operator": password}))
        tick_us = 1e6 / loop_rate_hz
        last = read_reply["tick"]
        endpoint.publish(0, t0_us, last + 1)  # ticks 0 .. the tick READ shows
        peer = RawPeer(endpoint.connect_in_memory())
        nonce = b""
        published = False
        for side, frame in lines:
            if side == "C":
                if frame[0] == "AUTH":
                    cnonce = os.urandom(32)
                    frame[2] = {"cnonce": cnonce, "mac": client_mac(password, nonce, cnonce)}
                await peer.send(frame)
                continue
            if frame[0] == "DATA" and not published:  # the device computes the next 409 ticks
                endpoint.publish(last + 1, t0_us + round_half_up((last + 1) * tick_us), 409)
                published = True
            got = await peer.recv()
            check(frame, got, f"{frame[0]} {frame[1]}")
            if frame[0] == "OK" and frame[1] == 1:
                nonce = got[2]["nonce"]
        assert await peer.recv() is None  # BYE: the endpoint closed
        await endpoint.close()

    run(main())


def test_the_example_sample_time_follows_the_rule_of_section_6() -> None:
    text = re.sub(r"\s+", " ", section("9"))
    m = re.search(r"its sample (\d+) was taken at tick (\d+) and mount time (\d+) \+ "
                  r"round_half_up\((\d+) × ([\d.]+)\) = (\d+) µs", text)
    assert m, "the sample-time sentence of §9 is missing"
    i, tick, first_t_us, i2, period_us, t_us = m.groups()
    second = next(v for side, v in exchange_lines() if side == "S" and v[0] == "DATA" and v[2] == 1)
    assert int(i) == int(i2) and int(tick) == second[3] + int(i) * second[6]
    assert int(first_t_us) == second[4] and float(period_us) == second[5]
    assert int(t_us) == second[4] + int(sample_offsets_us(second[5], int(i) + 1)[-1])
