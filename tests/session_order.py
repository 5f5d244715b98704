"""The order in which the suite's modules start (tests/conftest.py sorts the collected tests
with `longest_first`)."""

from __future__ import annotations

from pathlib import Path

TESTS = Path(__file__).parent

# The modules that take longest, longest first (wall time, mostly spent waiting on real or
# paced time, servers and browsers; measured per module with 4 workers by
# `bench_suite.py --modules`, last on 2026-11-27, which added the 55-80 s modules that had
# grown unlisted and so started in collection order, vss/ last): with `--dist loadscope`
# xdist hands modules out in collection order, so these start at once instead of one of
# them starting last and the others waiting for it at the end.
LONGEST_FIRST = (
    "hostile/test_hostile_vss.py",
    "anomalies/test_anomalies_on_recordings.py",
    "vss/test_vss_closed_loop.py",
    "backends/test_indi_sky.py",
    "backends/test_alpaca_sky.py",
    "anomalies/test_vss_nights.py",
    "vss/test_vss_demo_and_server.py",
    "panel/test_panel_reconnect_e2e.py",
    "recorder/test_recorder_crash.py",
    "backends/test_indi_pass.py",
    "hostile/test_hostile_api.py",
    "vss/test_vss_safety.py",
    "vss/test_vss_ownership_stateful.py",
    "vss/test_vss_on_target.py",
    "backends/test_alpaca_pass.py",
    "astcom/test_astcom_auth_throttle.py",
    "alpaca/test_alpaca_telescope.py",
    "astcom/test_astcom_hostile_input.py",
    "panel/test_panel_log_e2e.py",
    "panel/test_panel_js_client.py",
    "panel/test_panel_e2e.py",
    "planning/test_plan_night.py",
    "indi/test_indi_closed_loop.py",
    "anomalies/test_live_anomalies.py",
    "vss/test_vss_satellite.py",
    "device_c/test_device_qemu.py",
    "panel/test_panel_trust_e2e.py",
    "planning/test_run_night.py",
    "guide_camera/test_camera_truth.py",
    "indi/test_indi_driver.py",
    "panel/test_panel_c_device_e2e.py",
    "panel/test_panel_telescope_e2e.py",
    "alpaca/test_alpaca_closed_loop.py",
)


def longest_first(items: list) -> None:
    """Sort the collected tests in place: the modules of LONGEST_FIRST first, in its order; the
    rest as collected (a stable sort: the same order in every worker, as xdist requires)."""
    rank = {str(TESTS / name): i for i, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(str(item.path), len(rank)))
