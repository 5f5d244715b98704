"""Mount clock: microsecond time, crystal drift, UTC second applied on the 1 PPS edge."""

from __future__ import annotations

import pytest
from emulator_helpers import START_US, ticks

from mount_emulator import layout as L
from mount_emulator.model import MountModel
from mount_emulator.states import STATUS_SYNC_ARMED, STATUS_TIME_SYNCED


def test_utc_second_lands_exactly_on_the_next_pps_edge():
    m = MountModel(start_us=START_US + 300_000)  # 0.3 s past a whole second
    m.set_param("time.drift_ppm", 0.0)
    target_s = START_US // 1_000_000 + 1000  # deliberately far from the current second
    m.set_utc(target_s)
    assert int(m.state[L.G_STATUS]) & STATUS_SYNC_ARMED
    m.run(ticks(0.7) - 1)  # the tick before the edge
    assert m.mount_time_us == START_US + 1_000_000 - 100
    m.run(1)  # the edge: true time is on the whole second
    assert m.true_time_us % 1_000_000 == 0
    assert m.mount_time_us == target_s * 1_000_000
    assert int(m.state[L.G_STATUS]) & STATUS_TIME_SYNCED
    assert not int(m.state[L.G_STATUS]) & STATUS_SYNC_ARMED
    m.run(ticks(1.0))
    assert m.mount_time_us == (target_s + 1) * 1_000_000
    assert m.state[L.G_PENDING_UTC_S] == -1


@pytest.mark.parametrize("drift_ppm", [20.0, -7.5])
def test_mount_clock_drifts_by_the_crystal_error_between_syncs(drift_ppm):
    m = MountModel(start_us=START_US)
    m.set_param("time.drift_ppm", drift_ppm)
    m.run(ticks(10.0))
    drift_us = m.mount_time_us - m.true_time_us
    assert drift_us == pytest.approx(10.0 * drift_ppm, abs=1.0)
    # the PPS edge measures the clock error; a sync at the next edge removes it
    assert m.state[L.G_PPS_ERR_US] == pytest.approx(10.0 * drift_ppm, abs=1.0)
    m.set_utc(m.true_time_us // 1_000_000 + 1)
    m.run(ticks(1.0))
    assert m.mount_time_us == m.true_time_us
