"""What an independent implementer met (issue 17), each as the behaviour the spec now states."""

from __future__ import annotations

import struct
import subprocess
import sys

import msgpack
import numpy as np
import pytest
import websockets
from astcom_helpers import PASSWORDS, RawPeer, device_in_thread, memory_client, run, served
from device_impls import ALL_IMPLS, serve_impl

from astcom_client.codec import Codec, CodecLimits
from astcom_client.exceptions import LimitExceeded, MalformedFrame
from astcom_client.service import MAX_PERIOD_TICKS


def error_of(frame) -> tuple[int, str]:
    assert frame is not None and frame[0] == "ERR", frame
    return frame[2]["code"], frame[2]["message"]


async def logged_in_peer(dut) -> RawPeer:
    peer = RawPeer(await dut.connect())
    assert (await peer.login())[0] == "OK"
    return peer


@pytest.mark.parametrize("rate_hz", [1e-16, 5e-324, 1e-12, 1000 / MAX_PERIOD_TICKS / 2])
@pytest.mark.parametrize("impl", ALL_IMPLS)
def test_a_stream_rate_below_one_sample_per_2_32_ticks_is_refused_and_the_connection_stays(impl: str,
        rate_hz: float) -> None:
    async def main() -> None:
        async with serve_impl(impl) as dut:
            peer = await logged_in_peer(dut)
            msg = (await peer.request("DEFINE", {"names": ["counter"]}))[2]["msg"]
            code, text = error_of(await peer.request("STREAM_START", {"msg": msg,
                                                                       "rate_hz": rate_hz}))
            assert code == 422 and "2^32 ticks" in text
            ok = await peer.request("STREAM_START", {"msg": msg, "rate_hz": 1000 / MAX_PERIOD_TICKS})
            assert ok[0] == "OK" and ok[2]["period_ticks"] == MAX_PERIOD_TICKS < 2**53
    run(main())


@pytest.mark.parametrize("levels", [17, 1024, 1025, 5000])
def test_nesting_deeper_than_the_limit_is_413_at_any_depth(levels: int) -> None:
    codec = Codec(CodecLimits(max_depth=16))
    with pytest.raises(LimitExceeded, match="deeper than 16"):
        codec.decode(b"\x91" * levels + b"\xc0")


@pytest.mark.parametrize(("header", "error", "words"), [
    (b"\xdb\xff\xff\xff\xff", MalformedFrame, "truncated"),          # str32 of 4 GB
    (b"\xc6\xff\xff\xff\xff", MalformedFrame, "truncated"),          # bin32
    (b"\xc9\xff\xff\xff\xff\x01", MalformedFrame, "truncated"),      # ext32
    (b"\xdd\xff\xff\xff\xff", LimitExceeded, "max_array_len"),       # array32: count first
    (b"\xdf\xff\xff\xff\xff", LimitExceeded, "max_map_len"),         # map32
])
def test_a_declared_length_follows_the_settled_precedence(header: bytes, error: type,
                                                           words: str) -> None:
    with pytest.raises(error, match=words):
        Codec().decode(header)


def test_a_string_inside_the_frame_but_over_max_str_bytes_is_413() -> None:
    codec = Codec(CodecLimits(max_str_bytes=8))
    with pytest.raises(LimitExceeded):
        codec.decode(msgpack.packb("x" * 9))


def test_hello_announces_the_loop_rate_as_a_float_on_the_wire() -> None:
    async def main() -> None:
        async with served(loop_rate_hz=10_000) as (_, endpoint, _):
            peer = RawPeer(endpoint.connect_in_memory())
            await peer.send(["HELLO", 1, {"version": "1.0"}])
            raw = await peer.transport.recv()
            assert b"\xacloop_rate_hz\xcb" in raw  # key, then a float 64
    run(main())


@pytest.mark.parametrize("seq", [True, -1, 2**63, 1.5, "7"])
@pytest.mark.parametrize("impl", ALL_IMPLS)
def test_an_error_about_an_invalid_seq_carries_nil(impl: str, seq) -> None:
    async def main() -> None:
        async with serve_impl(impl) as dut:
            peer = await logged_in_peer(dut)
            await peer.send_raw(msgpack.packb(["PING", seq, {}]))
            reply = await peer.recv()
            assert reply[0] == "ERR" and reply[1] is None and reply[2]["code"] == 400
    run(main())


def test_an_ndarray_with_a_nonzero_reserved_field_is_refused() -> None:
    payload = struct.pack("<BBH", 10, 1, 7) + struct.pack("<I", 1) + b"\0" * 4 + b"\0" * 8
    frame = msgpack.packb(msgpack.ExtType(1, payload))
    with pytest.raises(MalformedFrame, match="reserved"):
        Codec().decode(frame)


@pytest.mark.parametrize("impl", ALL_IMPLS)
def test_bool_elements_are_refused_in_a_numeric_array_as_a_bool_scalar_is(impl: str) -> None:
    async def main() -> None:
        async with serve_impl(impl) as dut:
            peer = await logged_in_peer(dut)
            for args in ([[1.0, True]], [np.array([True, False])]):
                code, text = error_of(await peer.request("INVOKE", {"name": "math.sum",
                                                                     "args": args}))
                assert code == 422 and "bool" in text
            scalar = await peer.request("INVOKE", {"name": "math.add", "args": [True, 1.0]})
            assert error_of(scalar)[0] == 422
            fine = await peer.request("INVOKE", {"name": "math.sum", "args": [[1.0, 2]]})
            assert fine[2]["value"] == 3.0
    run(main())


def test_the_426_close_says_why() -> None:
    async def main() -> None:
        async with served("ws://127.0.0.1:0") as (_, _, url), websockets.connect(url) as ws:
            await ws.send(msgpack.packb(["HELLO", 1, {"version": "2.0"}]))
            reply = msgpack.unpackb(await ws.recv())
            assert reply[0] == "ERR" and reply[2]["code"] == 426
            with pytest.raises(websockets.ConnectionClosed) as closed:
                await ws.recv()
            assert closed.value.rcvd.reason.startswith("426 protocol version '2.0'")
    run(main())


@pytest.mark.parametrize("impl", ALL_IMPLS)
def test_define_of_a_function_says_it_is_a_function_and_invoke_of_a_variable_likewise(impl: str) -> None:
    async def main() -> None:
        async with serve_impl(impl) as dut:
            peer = await logged_in_peer(dut)
            code, text = error_of(await peer.request("DEFINE", {"names": ["math.add"]}))
            assert code == 404 and "is a function" in text and "did you mean" not in text
            code, text = error_of(await peer.request("INVOKE", {"name": "counter"}))
            assert code == 404 and "is a variable" in text
            code, text = error_of(await peer.request("DEFINE", {"names": ["countr"]}))
            assert "did you mean counter" in text
    run(main())


def _astcom(*args: str, timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "astcom_client.cli", *args],
                          capture_output=True, text=True, timeout=timeout)


def test_astcom_list_in_a_pipe_prints_whole_names_one_per_line() -> None:
    with device_in_thread(n_extra_signals=3) as dev:
        done = _astcom("list", dev["url"], "--password", PASSWORDS["operator"])
    assert done.returncode == 0, done.stderr
    names = [line.split("\t")[0] for line in done.stdout.splitlines()]
    assert "wave.sine" in names and "counter.reset" in names
    assert all("…" not in line for line in done.stdout.splitlines())


def test_astcom_stream_of_a_function_names_astcom_call() -> None:
    with device_in_thread() as dev:
        done = _astcom("stream", dev["url"], "math.add", "--password", PASSWORDS["operator"],
                       "--duration", "0.5")
    assert done.returncode == 1
    assert "is a function" in done.stderr and "astcom call" in done.stderr


def test_astcom_stream_reports_an_endpoint_that_goes_away_without_a_traceback() -> None:
    import asyncio
    import time

    with device_in_thread() as dev:
        proc = subprocess.Popen([sys.executable, "-m", "astcom_client.cli", "stream", dev["url"],
                                 "wave.sine", "--password", PASSWORDS["operator"],
                                 "--duration", "60", "--json"],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        endpoint = dev["endpoint"]
        deadline = time.monotonic() + 60
        while not len(endpoint.wanted_trace_columns):  # wait for the stream, then cut it
            assert time.monotonic() < deadline and proc.poll() is None, "no stream started"
            time.sleep(0.05)
        # the endpoint goes away under the streaming client
        asyncio.run_coroutine_threadsafe(endpoint.close(), dev["loop"]).result(30)
        out, err = proc.communicate(timeout=60)
    assert proc.returncode == 1, err
    assert "Traceback" not in err and "closed the connection" in err
    assert '"endpoint_closed": true' in out


def test_the_emulator_reports_its_loop_health() -> None:
    async def main() -> None:
        from mount_emulator import EmulatorConfig, MountEmulator

        emu = MountEmulator(EmulatorConfig(speed=0.0, start_us=1_763_769_600_000_000))
        emu.advance(100)
        emu._timed_advance(200)
        emu.health.woke(due_ticks=5_000, block_ticks=200, tick_us=100.0)
        client = await memory_client(emu.endpoint, password=None)
        async with client:
            values = await client.read(["loop.blocks", "loop.overruns", "loop.late_ticks",
                                        "loop.worst_block_us", "loop.worst_lag_us"])
            assert values["loop.blocks"] == 1 and values["loop.overruns"] == 1
            assert values["loop.late_ticks"] == 4_800 and values["loop.worst_lag_us"] == 500_000
            assert values["loop.worst_block_us"] > 0
            await client.invoke("loop.reset_health")
            assert (await client.read(["loop.overruns"]))["loop.overruns"] == 0
        await emu.endpoint.close()
    run(main())


def test_astcom_list_at_an_80_column_terminal_keeps_every_name_whole(monkeypatch) -> None:
    import io

    from rich.console import Console
    from typer.testing import CliRunner

    import astcom_client.cli as cli

    screen = io.StringIO()
    monkeypatch.setattr(cli, "out", Console(file=screen, width=80, force_terminal=True,
                                            color_system=None))
    with device_in_thread(n_extra_signals=12) as dev:
        result = CliRunner().invoke(cli.app, ["list", dev["url"], "--password",
                                              PASSWORDS["operator"]])
        names = [v.name for v in dev["device"].collection]
    assert result.exit_code == 0, result.output
    text = screen.getvalue()
    assert max(len(line) for line in text.splitlines()) <= 80
    assert all(name in text for name in names), [n for n in names if n not in text]
