"""Streams carry every k-th tick, with exact times, to any number of clients."""

import asyncio

import numpy as np
import pytest
from astcom_helpers import PASSWORDS, RawPeer, memory_client, memory_session, run, served, settle

from astcom_client import InvalidValue
from astcom_client.commands import StreamStop

RATE_HZ = 1000.0


async def collect(stream, n_packets: int, timeout_s: float = 5.0) -> list:
    return [await stream.get(timeout_s) for _ in range(n_packets)]


def test_stream_samples_match_the_signal_at_their_reconstructed_ticks_and_times() -> None:
    async def main() -> None:
        async with memory_session() as (device, endpoint, client):
            device.advance(endpoint, 3)  # start off the grid: sampling must align on tick % k
            stream = await client.stream(["counter", "wave.sine", "wave.cosine"], rate_hz=250)
            assert (stream.rate_hz, stream.period_ticks) == (250.0, 4)
            rng = np.random.default_rng(1)
            while stream.samples < 400:
                device.advance(endpoint, int(rng.integers(1, 30)))
                await settle()
            packets = [await stream.get(1.0) for _ in range(len(stream._queue))]
        ticks = np.concatenate([p.ticks for p in packets])
        t_us = np.concatenate([p.t_us for p in packets])
        values = np.concatenate([p.values for p in packets])
        assert ticks[0] == 4 and np.all(ticks % 4 == 0) and np.all(np.diff(ticks) == 4)
        assert sum(p.lost for p in packets) == 0
        np.testing.assert_array_equal(values[:, 0], ticks)
        phase = 2 * np.pi * 5.0 * ticks / RATE_HZ
        np.testing.assert_allclose(values[:, 1], np.sin(phase), atol=1e-12)
        np.testing.assert_allclose(values[:, 2], np.cos(phase), atol=1e-12)
        np.testing.assert_array_equal(t_us, device.start_t_us + ticks * 1000)
        assert [p.seq for p in packets] == list(range(len(packets)))
    run(main())


def test_two_clients_starting_apart_sample_the_same_ticks_and_share_one_sampler() -> None:
    async def main() -> None:
        async with memory_session() as (device, endpoint, first):
            second = await memory_client(endpoint)
            a = await first.stream(["counter"], rate_hz=100)
            device.advance(endpoint, 237)
            b = await second.stream(["counter"], rate_hz=100)
            assert endpoint.stats()["sampling_groups"] == 1
            device.advance(endpoint, 400)
            await settle()
            pa, pb = a._queue[-1], b._queue[-1]
            assert pa.seq == pb.seq and np.array_equal(pa.values, pb.values)
            assert np.all(pa.ticks % 10 == 0)
            await second.close()
    run(main())


def test_write_lands_between_two_ticks_while_the_loop_runs() -> None:
    async def main() -> None:
        async with served(realtime=True) as (_, endpoint, _):
            client = await memory_client(endpoint)
            stream = await client.stream(["pair.diff"], rate_hz=RATE_HZ)
            for i in range(40):
                await client.write({"pair.a": float(i), "pair.b": float(i)})
                await asyncio.sleep(0.002)
            await client.write({"pair.a": 1.0, "pair.b": 0.0})  # one write of a non-zero diff
            diffs = []
            while not diffs or diffs[-1][-1] != 1.0:
                diffs.append((await stream.get(5.0)).values[:, 0])
            diffs = np.concatenate(diffs)
            # Until the last write every sample shows a == b: no tick saw half a message.
            assert np.all(diffs[: np.argmax(diffs != 0)] == 0.0)
            assert set(np.unique(diffs)) == {0.0, 1.0}
            await client.close()
    run(main())


def test_untraced_and_array_variables_are_sampled_at_the_end_of_each_block() -> None:
    async def main() -> None:
        async with memory_session() as (device, endpoint, client):
            stream = await client.stream(["counter", "gains", "wave.amplitude"], rate_hz=RATE_HZ)
            assert stream.names == ("counter", "gains[0]", "gains[1]", "gains[2]", "wave.amplitude")
            device.advance(endpoint, 10)
            await client.write({"gains": [7.0, 8.0, 9.0], "wave.amplitude": 2.0})
            device.advance(endpoint, 30)
            await settle()
            values = np.concatenate([p.values for p in stream._queue])
        assert values.dtype == np.float64  # an i64 group and an f64 group assembled
        np.testing.assert_array_equal(values[:, 0], np.arange(40))
        np.testing.assert_array_equal(values[:10, 1:4], [[1.0, 0.1, 0.01]] * 10)
        np.testing.assert_array_equal(values[10:, 1:4], [[7.0, 8.0, 9.0]] * 30)
        np.testing.assert_array_equal(values[10:, 4], 2.0)
    run(main())


def test_a_stream_with_mixed_dtypes_keeps_each_column_in_its_own_dtype() -> None:
    async def main() -> None:
        async with memory_session() as (device, endpoint, client):
            stream = await client.stream(["wave.sine", "counter"], rate_hz=RATE_HZ)
            device.advance(endpoint, 40)
            await settle()
            packet = await stream.get(1.0)
        counter = packet.column("counter")
        assert counter.dtype == np.int64
        np.testing.assert_array_equal(counter, packet.ticks)
        assert packet.column("wave.sine").dtype == np.float64
        np.testing.assert_array_equal(packet.values[:, 1], counter)


def test_per_sample_callbacks_receive_each_time_and_row() -> None:
    async def main() -> None:
        async with memory_session() as (device, endpoint, client):
            stream = await client.stream(["counter"], rate_hz=500)
            seen: list[tuple[int, float]] = []
            stream.on_sample(lambda t_us, row: seen.append((t_us, float(row[0]))))
            device.advance(endpoint, 100)
            await settle()
        assert [c for _, c in seen] == list(range(0, 100, 2))
        assert [t for t, _ in seen] == [device.t_us_of(c) for c in range(0, 100, 2)]
    run(main())


def test_stream_requests_outside_the_rules_are_refused() -> None:
    async def main() -> None:
        async with memory_session() as (_, _, client):
            with pytest.raises(InvalidValue, match="loop rate"):
                await client.stream(["counter"], rate_hz=2 * RATE_HZ)
            with pytest.raises(InvalidValue, match="rate_hz"):
                await client.stream(["counter"], rate_hz=0)
            with pytest.raises(InvalidValue, match="label"):
                await client.stream(["counter", "label"], rate_hz=10)
            info = await client.define(["counter"])
            with pytest.raises(KeyError, match="no stream"):
                await client._request(StreamStop(info.msg))
    run(main())


def test_stop_and_undefine_end_the_stream_and_free_the_sampler() -> None:
    async def main() -> None:
        async with memory_session() as (device, endpoint, client):
            stream = await client.stream(["counter"], rate_hz=RATE_HZ)
            device.advance(endpoint, 100)
            await stream.stop()
            assert endpoint.stats()["sampling_groups"] == 0
            device.advance(endpoint, 100)
            await settle()
            assert stream.samples <= 100
            other = await client.stream(["wave.sine"], rate_hz=RATE_HZ)
            await client.undefine(["wave.sine"])
            assert other.stopped and endpoint.stats()["streams"] == 0
            assert endpoint.stats()["messages"] == 1  # only ["counter"] is still defined
    run(main())


def test_endpoint_drops_oldest_packets_for_a_stalled_client() -> None:
    async def main() -> None:
        async with served(queue_packets=4, flush_interval_s=0.01) as (device, endpoint, _):
            healthy = await memory_client(endpoint)
            good = await healthy.stream(["counter"], rate_hz=RATE_HZ)
            peer = RawPeer(endpoint.connect_in_memory(maxsize=2))
            await peer.login()
            msg = (await peer.request("DEFINE", {"names": ["counter"]}))[2]["msg"]
            await peer.request("STREAM_START", {"msg": msg, "rate_hz": RATE_HZ})
            for _ in range(50):  # 50 packets of 10 samples; the raw peer reads none of them
                device.advance(endpoint, 10)
                await settle()
            stats = await healthy.stats()
            stalled = next(c for c in stats["per_client"] if c["name"] == "raw")
            assert stalled["dropped_samples"] > 0 and stalled["queue_depth"] <= 4
            assert good.samples == 500 and good.lost == 0
            frames = []
            while (frame := await peer.recv(0.2)) is not None:
                frames.append(frame)
                if len(frames) >= 2 + 4:  # what the transport and the queue held
                    break
            seqs = [f[2] for f in frames if f[0] == "DATA"]
            gap_samples = 10 * sum(b - a - 1 for a, b in zip(seqs, seqs[1:], strict=False))
            assert gap_samples == stalled["dropped_samples"]
            await healthy.close()
    run(main())


def test_a_raising_callback_does_not_break_the_connection() -> None:
    async def main() -> None:
        async with served("tcp://127.0.0.1:0") as (device, endpoint, url):
            from astcom_client import Client

            client = await Client.connect(url, password=PASSWORDS["operator"])
            stream = await client.stream(["counter"], rate_hz=RATE_HZ)
            calls = []

            def broken(packet) -> None:
                calls.append(packet.seq)
                raise RuntimeError("bug in user code")

            stream.on_packet(broken)
            while len(calls) < 3:  # several packets, each raising in the callback
                device.advance(endpoint, 20)
                await asyncio.sleep(0.01)
            assert client.connected
            assert await client.invoke("math.add", 1.0, 2.0) == 3.0
            await client.close()
    run(main())


def test_a_gap_in_the_device_ticks_ends_the_packet_and_counts_as_skipped_not_lost() -> None:
    async def main() -> None:
        async with memory_session() as (device, endpoint, client):
            stream = await client.stream(["counter"], rate_hz=RATE_HZ)  # 20 samples per packet
            device.advance(endpoint, 30)
            device.tick += 100  # the device skips 100 ticks (e.g. a paused simulation)
            device.advance(endpoint, 30)
            await settle()
            packets = list(stream._queue)
        ticks = [p.ticks.tolist() for p in packets]
        assert ticks[0] == list(range(20)) and ticks[1] == list(range(20, 30))
        assert ticks[2] == list(range(130, 150))
        # seq went on by one: the device skipped the ticks, no packet was dropped (spec §6)
        assert [p.seq for p in packets] == [0, 1, 2] and packets[2].lost == 0
        assert stream.skipped_samples == 100 and stream.lost == 0
        for packet in packets:  # counter == tick everywhere: no packet spans the gap
            np.testing.assert_array_equal(packet.column("counter"), packet.ticks)
    run(main())


def test_a_second_connection_can_carry_the_stream_alone_with_the_shared_message_id() -> None:
    async def main() -> None:
        async with memory_session() as (device, endpoint, control):
            streamer = await memory_client(endpoint, name="recorder")
            names = ["counter", "wave.sine"]
            assert (await control.define(names)).msg == (await streamer.define(names)).msg
            stream = await streamer.stream(names, rate_hz=500)
            await control.write({"wave.amplitude": 2.0})  # requests on the first connection
            device.advance(endpoint, 100)
            await settle()
            assert stream.samples == 50
            stats = await control.stats()
            by_name = {c["name"]: c for c in stats["per_client"]}
            assert by_name["recorder"]["streams"] == 1 and by_name["astcom-client"]["streams"] == 0
            await streamer.undefine(names)
            assert endpoint.stats()["messages"] == 2  # still held by the first connection
            await control.undefine(names)
            assert endpoint.stats()["messages"] == 1  # ["wave.amplitude"] from the write
            await streamer.close()
    run(main())


def test_an_f32_slot_backed_by_float64_state_reads_and_streams_in_single_precision() -> None:
    from astcom_client import Client, Collection, Endpoint, EndpointConfig

    async def main() -> None:
        state = np.zeros(2)  # the device keeps float64, as the mount emulator does
        coll = Collection()
        coll.add_slot("a.position", state, 0, type="f64", traced=True)
        coll.add_slot("a.current", state, 1, type="f32", unit="A", traced=True)
        endpoint = Endpoint(coll, EndpointConfig(loop_rate_hz=1000.0, passwords=None))
        client = await Client.open(endpoint.connect_in_memory())
        try:
            state[:] = [0.1, 0.1]
            read = await client.read(["a.position", "a.current"])
            both = await client.stream(["a.position", "a.current"], rate_hz=RATE_HZ)
            alone = await client.stream(["a.current"], rate_hz=RATE_HZ)
            trace = np.empty((40, 2))
            trace[:, 0] = trace[:, 1] = 1.0 / 3.0 + np.arange(40) * 0.1
            endpoint.publish(0, 0, 40, trace)
            await settle()
            mixed, single = await both.get(1.0), await alone.get(1.0)
        finally:
            await client.close()
            await endpoint.close()
        assert read["a.position"] == 0.1
        assert read["a.current"] == float(np.float32(0.1)) != 0.1
        expected = trace[:len(mixed.t_us), 1].astype(np.float32)
        assert mixed.column("a.current").dtype == np.float32
        assert mixed.column("a.current").tobytes() == expected.tobytes()
        assert mixed.column("a.position").tobytes() == trace[:len(mixed.t_us), 0].tobytes()
        assert single.values.dtype == np.float32
        assert single.values[:, 0].tobytes() == expected.tobytes()
    run(main())
