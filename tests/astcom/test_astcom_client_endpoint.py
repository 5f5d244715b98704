"""A Client and an Endpoint agree on every command, in memory and over real sockets."""

import asyncio
import time

import numpy as np
import pytest
from astcom_helpers import PASSWORDS, memory_client, memory_session, run, served, settle

from astcom_client import (
    AuthenticationFailed,
    Client,
    DeviceError,
    Forbidden,
    InvalidValue,
    NotWritable,
    TimestampUs,
    TooMany,
    UnknownName,
)


def test_list_describes_every_variable_and_function() -> None:
    async def main() -> None:
        async with memory_session() as (device, endpoint, client):
            entries = {e.name: e for e in await client.list()}
        expected = {e.name for e in device.collection}
        assert set(entries) == expected
        assert entries["wave.amplitude"].kind == "parameter"
        assert entries["wave.amplitude"].access == "rw"
        assert entries["wave.amplitude"].unit == "V"
        assert entries["math.add"].type == "(a:f64,b:f64)->f64"
        assert entries["gains"].type == "f64[3]"
        assert entries["power.limits.current_a"].unit == "A"
    run(main())


def test_read_returns_the_values_of_one_tick() -> None:
    async def main() -> None:
        async with memory_session(password=PASSWORDS["observer"]) as (device, endpoint, client):
            device.advance(endpoint, 37)
            values, tick, t_us = await client.read_at(["counter", "wave.sine", "gains", "site"])
            assert tick == 36 and values["counter"] == 36
            assert t_us == device.t_us_of(36)
            expected = np.sin(2 * np.pi * 5.0 * 36 / 1000.0)
            assert values["wave.sine"] == pytest.approx(expected, abs=1e-12)
            assert values["gains"].tolist() == [1.0, 0.1, 0.01]
            assert values["site"] == {"lat_deg": 45.0, "lon_deg": 6.0}
    run(main())


def test_write_sets_every_value_of_the_message() -> None:
    async def main() -> None:
        async with memory_session() as (device, endpoint, client):
            await client.write({"wave.amplitude": 3, "gains": [4, 5, 6], "label": "m1",
                                "power.limits.enabled": False})
            assert device.params[0] == 3.0
            assert device.gains.tolist() == [4.0, 5.0, 6.0]
            assert device.state.label == "m1"
            assert device.power.limits.enabled is False
    run(main())


def test_a_write_with_one_bad_value_changes_nothing() -> None:
    async def main() -> None:
        async with memory_session() as (device, endpoint, client):
            with pytest.raises(InvalidValue, match="gains"):
                await client.write({"wave.amplitude": 7.0, "gains": [1.0, 2.0]})
            assert device.params[0] == 1.0
            with pytest.raises(NotWritable, match="counter"):
                await client.write({"wave.amplitude": 7.0, "counter": 3})
            assert device.params[0] == 1.0
    run(main())


def test_invoke_passes_typed_arguments_and_returns_the_value() -> None:
    async def main() -> None:
        async with memory_session() as (device, endpoint, client):
            assert await client.invoke("math.add", 1.5, 2) == 3.5
            assert await client.invoke("math.sum", np.arange(10.0)) == 45.0
            assert await client.invoke("device.wait", 0.01) == 0.01
            device.advance(endpoint, 12)
            assert await client.invoke("counter.reset") == 12
            with pytest.raises(DeviceError, match="always fails"):
                await client.invoke("device.fail")
            with pytest.raises(InvalidValue, match="takes 2 arguments"):
                await client.invoke("math.add", 1.0)
            with pytest.raises(UnknownName, match="math.ad"):
                await client.invoke("math.ad", 1.0, 2.0)
    run(main())


def test_observers_may_read_but_not_write_or_invoke() -> None:
    async def main() -> None:
        async with memory_session(password=PASSWORDS["observer"]) as (device, endpoint, client):
            assert client.role == "observer"
            await client.read(["wave.amplitude"])
            with pytest.raises(Forbidden, match="operator"):
                await client.write({"wave.amplitude": 2.0})
            with pytest.raises(Forbidden):
                await client.invoke("math.add", 1.0, 2.0)
            assert device.params[0] == 1.0
    run(main())


def test_a_wrong_password_is_refused_and_the_endpoint_serves_others() -> None:
    async def main() -> None:
        async with served() as (_, endpoint, _):
            with pytest.raises(AuthenticationFailed):
                await memory_client(endpoint, password="guess")
            with pytest.raises(AuthenticationFailed, match="requires a password"):
                await memory_client(endpoint, password=None)
            async with await memory_client(endpoint) as client:
                assert client.role == "operator"
            await settle()
            assert endpoint.stats()["clients"] == 0
    run(main())


def test_asking_for_the_observer_role_downgrades_an_operator_password() -> None:
    async def main() -> None:
        async with memory_session(client_options={"role": "observer"}) as (_, endpoint, client):
            assert client.role == "observer"
    run(main())


@pytest.mark.parametrize("scheme", ["ws", "tcp"])
def test_every_command_works_over_a_real_loopback_socket(scheme: str) -> None:
    async def main() -> None:
        async with served(f"{scheme}://127.0.0.1:0", realtime=True) as (device, endpoint, url):
            assert url is not None and url.startswith(f"{scheme}://127.0.0.1:")
            async with await Client.connect(url, password=PASSWORDS["operator"]) as client:
                assert len(await client.list()) == len(device.collection)
                await client.write({"wave.offset": 10.0})
                values = await client.read(["wave.offset", "wave.sine"])
                assert values["wave.offset"] == 10.0
                assert await client.invoke("math.add", 2.0, 3.0) == 5.0
                stream = await client.stream(["counter", "wave.sine"], rate_hz=500)
                packet = await stream.get(timeout_s=5.0)
                assert np.all(np.diff(packet.column("counter")) == 2)
                await stream.stop()
                assert (await client.stats())["clients"] == 1
            while endpoint.stats()["clients"]:  # the session ends after the client's BYE
                await asyncio.sleep(0.01)
    run(main())


@pytest.mark.parametrize("scheme", ["ws", "tcp"])
def test_a_socket_client_learns_why_it_is_refused_or_dropped(scheme: str) -> None:
    async def main() -> None:
        async with served(f"{scheme}://127.0.0.1:0", max_clients=1) as (_, endpoint, url):
            with pytest.raises(AuthenticationFailed):
                await Client.connect(url, password="wrong")
            while endpoint.stats()["clients"]:  # the refused session is still ending
                await asyncio.sleep(0.01)
            first = await Client.connect(url, password=PASSWORDS["observer"])
            with pytest.raises(TooMany, match="at most 1"):
                await Client.connect(url, password=PASSWORDS["observer"])
            await endpoint.close()
            with pytest.raises(ConnectionError):
                await first.read(["counter"])
            assert not first.connected
    run(main())


def test_ping_gives_the_host_wall_clock_and_the_mount_time_of_the_last_tick() -> None:
    async def main() -> None:
        t0_us = 1_000_000_000_000_000  # mount time far from the wall clock (2001)
        async with memory_session() as (_, endpoint, client):
            first = await client.ping()
            assert first["tick"] == -1 and first["tick_t_us"] is None
            endpoint.publish(0, t0_us, 10)  # loop 1000 Hz: tick 9 at t0 + 9 ms
            before_us = time.time_ns() // 1000
            reply = await client.ping()
            after_us = time.time_ns() // 1000
            assert reply["tick"] == 9 and reply["tick_t_us"] == t0_us + 9_000
            assert isinstance(reply["t_us"], TimestampUs)
            assert before_us <= reply["t_us"].t_us <= after_us  # the host's clock, not the mount's
    run(main())


def test_a_refusal_that_arrives_before_the_hello_is_sent_is_reported_as_the_refusal() -> None:
    """An endpoint (or a Relay) at its limit says ERR 429 and closes at once; when its
    handshake reply, the ERR and the close arrive in one read, the client's HELLO finds
    the WebSocket closing. The caller must still get TooMany with the endpoint's reason."""
    import msgpack
    from websockets.server import ServerProtocol

    async def refuse(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        ws = ServerProtocol()
        events: list = []
        while not events:
            ws.receive_data(await reader.read(4096))
            events = ws.events_received()
        ws.send_response(ws.accept(events[0]))
        ws.send_binary(msgpack.packb(["ERR", None, {"code": 429, "message":
                                      "too many clients: this endpoint accepts at most 2"}]))
        ws.send_close(1008, "too many clients")
        writer.write(b"".join(ws.data_to_send()))  # all in one segment
        await writer.drain()
        await reader.read(4096)
        writer.close()

    async def main() -> None:
        server = await asyncio.start_server(refuse, "127.0.0.1", 0)
        port = server.sockets[0].getsockname()[1]
        try:
            for _ in range(5):
                with pytest.raises(TooMany, match="at most 2"):
                    await Client.connect(f"ws://127.0.0.1:{port}", password=PASSWORDS["operator"])
        finally:
            server.close()
    run(main())


def test_a_request_whose_send_fails_raises_once_and_leaves_no_unretrieved_error() -> None:
    """The request raises ConnectionClosed itself; its own pending future, failed with the
    same error, must not be logged as "Future exception was never retrieved" when it is
    collected (a suite printed that traceback at exit)."""
    import gc

    from astcom_client import ConnectionClosed

    unhandled: list[dict] = []

    async def main() -> None:
        asyncio.get_running_loop().set_exception_handler(lambda _, ctx: unhandled.append(ctx))
        async with memory_session() as (_, _, client):
            client._transport.closed = True  # the link drops between two requests
            with pytest.raises(ConnectionClosed):
                await client.read(["counter"])
            gc.collect()
            await settle()
    run(main())
    gc.collect()
    assert not [c for c in unhandled if "never retrieved" in str(c.get("message", ""))], unhandled
