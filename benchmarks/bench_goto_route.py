"""How near the Sun a goto mount's own slews come on a detour, planned two ways (issue 30).

For the backend scenario's slew round the Sun (latitude −30°, the Sun ~50° high 2.5 h east,
the route's ends 40° × 1/cos el either side of it, a 30° zone) on four dates across the
seasons, the gotos are planned by `goto_route` (each leg's box in RA/Dec of date clears the
zone by 1°) and, for reference in the same run, the way it was done before (the checked
route cut into equal az/el steps of ≤ 20°). Both ways a driver slews — linearly in RA/Dec
(the Alpaca simulator), each axis at its own speed (the INDI simulator) — are flown between
the waypoints, and every place is judged against astropy's Sun. Printed: the closest
approach, the number of gotos, and how long the planning took.

Usage: python benchmarks/bench_goto_route.py
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "backends"))
sys.path.insert(0, str(ROOT))


def main() -> None:
    import warnings

    from test_goto_route import INSTANTS_UTC, SUN_RADIUS_DEG, _closest_approach_deg, _route

    from virtualstar.astro import EarthOrientation

    warnings.simplefilter("ignore")
    eop = EarthOrientation.from_astropy_iers_data()
    print(f"zone {SUN_RADIUS_DEG:g}°; closest approach of the driver's own slews to astropy's "
          "Sun (linear RA/Dec | each axis at its speed)")
    print(f"{'date (UTC)':22s} {'plan':16s} {'gotos':>5s} {'linear':>8s} {'axes':>8s} "
          f"{'plan ms':>8s}")
    worst = {"goto_route": 90.0, "20° steps": 90.0}
    for iso in INSTANTS_UTC:
        for name, step in (("goto_route", None), ("20° steps", 20.0)):
            t0 = time.perf_counter()
            site, t_us, start, gotos = _route(iso, eop, step)
            plan_ms = (time.perf_counter() - t0) * 1e3
            seps = [_closest_approach_deg(site, t_us, start, gotos, way)
                    for way in ("linear", "axes")]
            worst[name] = min(worst[name], *seps)
            flag = "" if min(seps) > SUN_RADIUS_DEG else "  ✘ inside the zone"
            print(f"{iso:22s} {name:16s} {len(gotos):5d} {seps[0]:8.2f} {seps[1]:8.2f} "
                  f"{plan_ms:8.0f}{flag}")
    print(f"closest of all: goto_route {worst['goto_route']:.2f}°, 20° steps "
          f"{worst['20° steps']:.2f}° (reference, same run)")


if __name__ == "__main__":
    main()
