"""The VSS on ASCOM's alpaca-simulators: an ISS-like pass, stop mid-pass, the driver killed (pass_checks.py; real time)."""

import pytest

pytest.register_assert_rewrite("pass_checks")

from pass_checks import *  # noqa: E402, F403
from scenario_run import SCENARIO_TIMEOUT_S, scenario_fixture  # noqa: E402

pytestmark = pytest.mark.timeout(SCENARIO_TIMEOUT_S + 60)
seen = scenario_fixture("alpaca", "pass")
