"""Plan a program over a night: the one call behind `vs plan` (and `vs run`'s re-planning)."""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

from virtualstar.astro import AvoidanceZones, EarthOrientation, MountLimits, Site

from .program import Program
from .scheduler import EMULATOR_LIMITS, PARK_AZ_DEG, PARK_EL_DEG, SETUP_S, Plan, schedule
from .sky import DEFAULT_STEP_S, NightGrid, satellite_windows, target_skies

__all__ = ["PlanRequest", "plan_program"]


@dataclass(frozen=True)
class PlanRequest:
    """What to plan: a program between two mount times at a site, with its zones."""

    program: Program
    start_us: int
    end_us: int
    site: Site
    zones: AvoidanceZones = AvoidanceZones()
    limits: MountLimits = EMULATOR_LIMITS
    step_s: float = DEFAULT_STEP_S
    setup_s: float = SETUP_S
    skip: frozenset[str] = frozenset()  # targets already done (re-planning a running night)
    start_place_deg: tuple[float, float] = (PARK_AZ_DEG, PARK_EL_DEG)  # mount az, el at start
    # "altaz", "fork" or "german" (a backend's capabilities.geometry): a German mount
    # follows a pass on one side of the meridian only (it would flip in between)
    mount_geometry: str = "altaz"


def plan_program(req: PlanRequest, eop: EarthOrientation | None = None) -> Plan:
    """Return the plan; `plan.site` and the planning time (`timing_s`) are filled in."""
    t0 = time.perf_counter()
    eop = eop or EarthOrientation.from_astropy_iers_data()
    grid = NightGrid.build(req.start_us, req.end_us, req.site, eop, req.step_s)
    targets = [t for t in req.program.targets if t.name not in req.skip]
    skies = target_skies([t for t in targets if not t.is_satellite], grid, req.site, eop,
                         req.zones)
    satellites = [t for t in targets if t.is_satellite]
    passes = {t.name: satellite_windows(t, grid, req.site, eop, req.zones,
                                        mount_geometry=req.mount_geometry)
              for t in satellites}
    plan = schedule(req.program.name, grid, skies, passes, satellites, limits=req.limits,
                    setup_s=req.setup_s, start_place_deg=req.start_place_deg)
    plan.site = dataclasses.asdict(req.site)
    plan.program_spec = req.program.as_dict()
    plan.timing_s = time.perf_counter() - t0  # type: ignore[attr-defined]
    return plan
