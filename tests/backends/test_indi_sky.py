"""The VSS on INDI's indi_simulator_telescope (indiserver): a star, `vs run`, the Sun refused, a slew round it (sky_checks.py; real time)."""

import pytest

pytest.register_assert_rewrite("sky_checks")

from scenario_run import SCENARIO_TIMEOUT_S, scenario_fixtures  # noqa: E402
from sky_checks import *  # noqa: E402, F403

pytestmark = pytest.mark.timeout(SCENARIO_TIMEOUT_S + 60)
seen_parts, seen, seen_route = scenario_fixtures("indi", "sky", "route")
