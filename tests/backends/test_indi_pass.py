"""The VSS on INDI's indi_simulator_telescope (indiserver): an ISS-like pass, stop mid-pass, the driver killed (pass_checks.py; real time)."""

import pytest

pytest.register_assert_rewrite("pass_checks")

from pass_checks import *  # noqa: E402, F403
from scenario_run import SCENARIO_TIMEOUT_S, scenario_fixtures  # noqa: E402

pytestmark = pytest.mark.timeout(SCENARIO_TIMEOUT_S + 60)
seen_parts, seen, seen_kill = scenario_fixtures("indi", "pass", "kill")
