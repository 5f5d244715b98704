"""Parameter limits: declared in the registry, shown by LIST, enforced whole by WRITE (422)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from astcom_helpers import memory_session, run
from typer.testing import CliRunner

from astcom_client import Client, Collection
from astcom_client.cli import app
from astcom_client.exceptions import InvalidValue


def test_list_shows_the_range_of_bounded_parameters_and_no_range_for_the_others():
    async def scenario():
        async with memory_session() as (device, _endpoint, client):
            return {e.name: e for e in await client.list()}, device.loop_rate_hz

    entries, rate = run(scenario())
    amp = entries["wave.amplitude"]
    assert (amp.min, amp.max, amp.unit) == (0.0, 100.0, "V")
    assert entries["wave.frequency_hz"].max == rate / 2
    assert (entries["wave.offset"].min, entries["wave.offset"].max) == (None, None)
    assert entries["wave.offset"].as_dict().keys() == {"name", "type", "kind", "access", "unit",
                                                       "doc"}


def test_a_write_outside_the_range_is_refused_and_nothing_of_the_message_is_applied():
    async def scenario():
        async with memory_session() as (device, _endpoint, client):
            before = await client.read(["wave.amplitude", "wave.offset", "gains"])
            with pytest.raises(InvalidValue) as low:
                await client.write({"wave.offset": 5.0, "wave.amplitude": -30.0})
            with pytest.raises(InvalidValue) as high:
                await client.write({"gains": [1.0, 2000.0, 3.0]})
            with pytest.raises(InvalidValue) as nan:
                await client.write({"wave.amplitude": math.nan})
            after = await client.read(["wave.amplitude", "wave.offset", "gains"])
            await client.write({"wave.amplitude": 100.0})  # the bound itself is allowed
            edge = await client.read(["wave.amplitude"])
            return before, after, low.value, high.value, nan.value, edge

    before, after, low, high, nan, edge = run(scenario())
    assert low.code == 422 and "wave.amplitude = -30 V is below its minimum 0 V" in str(low)
    assert "allowed 0..100 V" in str(low)
    assert high.code == 422 and "gains = 2000 is above its maximum 1000" in str(high)
    assert nan.code == 422
    assert after["wave.offset"] == before["wave.offset"]  # the valid half was not applied
    assert after["wave.amplitude"] == before["wave.amplitude"]
    assert np.array_equal(after["gains"], before["gains"])
    assert edge["wave.amplitude"] == 100.0


@pytest.mark.parametrize(("kwargs", "words"), [
    ({"type": "str", "min_value": 0.0}, "only numeric"),
    ({"type": "f64", "min_value": 5.0, "max_value": 1.0}, "above max_value"),
    ({"type": "f64", "max_value": math.inf}, "finite"),
])
def test_a_device_cannot_declare_a_nonsense_range(kwargs, words):
    coll = Collection()
    with pytest.raises(ValueError, match=words):
        coll.add_variable("x", kind="parameter", access="rw", get=lambda: 0,
                          set=lambda v: None, **kwargs)


def test_the_emulator_refuses_a_negative_position_gain_and_keeps_its_own():
    import asyncio

    from virtualstar.launcher import start_emulator

    async def scenario():
        emu = await start_emulator(speed=1.0)
        try:
            async with await Client.connect(emu.url) as c:
                entries = {e.name: e for e in await c.list("axis.az.")}
                kp = (await c.read(["axis.az.kp"]))["axis.az.kp"]
                result = await asyncio.to_thread(CliRunner().invoke, app,
                                                 ["set", emu.url, "axis.az.kp", "--", "-30"])
                after = await c.read(["axis.az.kp", "mount.state_name"])
        finally:
            await emu.stop()
        return entries, kp, result, after

    entries, kp, result, after = asyncio.run(scenario())
    assert entries["axis.az.kp"].min == 0.0 and entries["axis.az.kp"].max == pytest.approx(10 * kp)
    assert entries["axis.az.rate_limit"].min > 0 and entries["axis.az.velocity_ff"].max == 1.0
    assert result.exit_code == 2 and "below its minimum 0" in result.stderr, result.output
    assert after["axis.az.kp"] == kp and after["mount.state_name"] != "FAULT"
