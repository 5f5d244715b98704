"""Sample times follow the spec's exact rule, so Python and JavaScript clients agree to the µs."""

import json
import math
import shutil
import subprocess
from fractions import Fraction

import numpy as np
import pytest
from astcom_helpers import memory_client, run, served, settle

from astcom_client.timing import round_half_up, sample_offsets_us

T0_US = 1_763_769_600_000_000


def reference_offset_us(i: int, period_us: float) -> int:
    """round_half_up of the double product i * period_us, computed with exact rationals."""
    product = Fraction(float(i) * period_us)  # the double product, exactly
    return math.floor(product + Fraction(1, 2))


@pytest.mark.parametrize("loop_rate_hz", [400_000.0, 3000.0, 7.0])
def test_packet_sample_times_round_half_up_the_double_product(loop_rate_hz: float) -> None:
    async def main() -> None:
        async with served(loop_rate_hz=loop_rate_hz, flush_interval_s=40 / loop_rate_hz,
                          passwords=None) as (_, endpoint, _):
            client = await memory_client(endpoint, password=None)
            stream = await client.stream(["counter"], rate_hz=loop_rate_hz)
            assert stream.samples_per_packet == 40
            tick_us = Fraction(10**6) / Fraction(loop_rate_hz)
            endpoint.publish(0, T0_US, 80)
            await settle()
            for _ in range(2):
                packet = await stream.get(timeout_s=2.0)
                expected = [packet.first_t_us + reference_offset_us(i, packet.period_us)
                            for i in range(packet.n)]
                assert packet.t_us.tolist() == expected
                # computed once a packet, and nobody's to change: a second reader sees the same
                assert packet.t_us is packet.t_us and not packet.t_us.flags.writeable
                # the endpoint's first_t_us of a packet follows the same rule from the block's start
                assert packet.first_t_us == T0_US + math.floor(
                    Fraction(float(packet.first_tick) * float(tick_us)) + Fraction(1, 2))
            await client.close()
    run(main())


def test_ties_round_up_not_to_even() -> None:
    assert sample_offsets_us(2.5, 6).tolist() == [0, 3, 5, 8, 10, 13]
    assert [round_half_up(x) for x in (0.5, 1.5, 2.5, 0.49999999999999994)] == [1, 2, 3, 0]


def test_python_and_javascript_agree_on_sample_times() -> None:
    node = shutil.which("node")
    if node is None:
        pytest.fail("node is not installed: the panel needs Node >= 20 (see setup/30-panel.sh)")
    periods = [2.5, 0.5, 100.0, 1e6 / 3000, 1e6 / 7, 12.5, 1e6 / 48000, 0.1, 333.3333333333333,
               1e6 / 400000 * 3, 2.0000000000000004]
    n = 5000
    script = ("const ps = JSON.parse(process.argv[1]); const n = Number(process.argv[2]);"
              "console.log(JSON.stringify(ps.map((p) => Array.from({length: n}, (_, i) => Math.round(i * p)))));")
    out = subprocess.run([node, "-e", script, json.dumps(periods), str(n)], capture_output=True,
                         text=True, check=True, timeout=60).stdout
    js = json.loads(out)
    for period, js_offsets in zip(periods, js, strict=True):
        ours = sample_offsets_us(period, n)
        assert np.array_equal(ours, np.array(js_offsets, dtype=np.int64)), period
        assert [round_half_up(i * period) for i in range(0, n, 97)] == js_offsets[::97]
