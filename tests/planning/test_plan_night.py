"""`vs plan`: every block meets its target's constraints (checked at one-second steps with
astropy for the sidereal targets and skyfield for the satellites), blocks never overlap,
slew gaps suffice, left-out targets say why, and a plan is deterministic."""

from __future__ import annotations

import math

import numpy as np
import pytest
from astropy.utils import iers
from sky_truth import observed_frame

from catalogs import load_tle_file, select_satellite
from virtualstar.astro import AvoidanceZones, EarthOrientation, MountLimits, load_site
from virtualstar.planning import PlanRequest, load_program, plan_program
from virtualstar.planning.scheduler import EMULATOR_LIMITS, Block, Plan, mount_chain
from virtualstar.planning.sky import night_window

iers.conf.auto_download = False
iers.conf.auto_max_age = None

EXAMPLE = "catalogs/data/program-example.toml"


@pytest.fixture(scope="module")
def eop():
    return EarthOrientation.from_astropy_iers_data()


@pytest.fixture(scope="module")
def site():
    return load_site()


@pytest.fixture(scope="module")
def example(eop, site):
    program = load_program(EXAMPLE)
    start_us, end_us = night_window("2024-05-18", site, eop)
    plan = plan_program(PlanRequest(program, start_us, end_us, site), eop)
    return program, plan


def _astropy_altaz(coord, t_us: np.ndarray, site):
    frame = observed_frame(t_us, site)
    return coord.transform_to(frame), frame


def _astropy_target(target):
    """The target as astropy sees it, built from the catalog entry or the RA/Dec text."""
    import astropy.units as u
    from astropy.coordinates import Distance, SkyCoord
    from astropy.time import Time

    from catalogs import bright_stars

    if target.kind == "radec":
        return SkyCoord(target.spec, frame="icrs")
    s = bright_stars().lookup(target.spec)
    return SkyCoord(ra=s.ra_deg * u.deg, dec=s.dec_deg * u.deg,
                    pm_ra_cosdec=s.pm_ra_cosdec_mas_yr * u.mas / u.yr,
                    pm_dec=s.pm_dec_mas_yr * u.mas / u.yr,
                    distance=Distance(parallax=s.parallax_mas * u.mas),
                    radial_velocity=(s.rv_km_s or 0.0) * u.km / u.s,
                    obstime=Time(s.epoch_jyear, format="jyear", scale="tcb"), frame="icrs")


def _every_second(block: Block) -> np.ndarray:
    return np.arange(block.start_us, block.end_us + 1, 1_000_000, dtype=np.int64)


def test_every_sidereal_block_meets_its_constraints_at_every_second_per_astropy(example, site):
    from astropy.coordinates import get_body

    program, plan = example
    by_name = {t.name: t for t in program.targets}
    zones = AvoidanceZones()
    sidereal = [b for b in plan.blocks if b.kind != "satellite"]
    assert len(sidereal) >= 5
    for block in sidereal:
        target = by_name[block.target]
        t_us = _every_second(block)
        coord = _astropy_target(target)
        if target.kind != "radec":
            from astropy.time import Time
            coord = coord.apply_space_motion(new_obstime=Time(t_us / 1e6, format="unix"))
        aa, frame = _astropy_altaz(coord, t_us, site)
        sun = get_body("sun", frame.obstime, frame.location).transform_to(frame)
        moon = get_body("moon", frame.obstime, frame.location).transform_to(frame)
        where = f"{block.target} #{block.repeat} at {block.as_dict()['start_utc']}"
        assert aa.alt.deg.min() >= max(target.min_el_deg, zones.el_min_deg) - 1e-3, where
        assert sun.alt.deg.max() <= target.sun_max_el_deg + 0.02, where
        assert aa.separation(sun).deg.min() >= zones.sun_radius_deg, where
        if target.moon_min_sep_deg:
            assert aa.separation(moon).deg.min() >= target.moon_min_sep_deg - 0.02, where
        if target.az_windows_deg:
            az = aa.az.deg
            assert target.az_allowed(az).all(), (where, az.min(), az.max())
        if target.window_us is not None:
            assert target.window_us[0] <= block.start_us and block.end_us <= target.window_us[1]
        assert abs(block.duration_s - target.duration_s) < 1e-6, where
        # the block's own figures are where astropy puts the target at its start
        assert abs(block.start_el_deg - aa.alt.deg[0]) < 0.01, where
        assert abs((block.start_az_deg - aa.az.deg[0] + 180) % 360 - 180) < 0.01, where


def _skyfield_satellite(eop, target):
    from skyfield.api import EarthSatellite

    from virtualstar.astro.bodies import skyfield_context

    sf = skyfield_context(eop)
    rec = select_satellite(load_tle_file(target.tle_file), target.spec)
    return EarthSatellite(rec.line1, rec.line2, rec.name, sf.ts), sf


def test_satellite_blocks_lie_in_skyfields_passes_and_meet_sunlit_while_dark(example, site, eop):
    from skyfield.api import wgs84

    program, plan = example
    sats = [b for b in plan.blocks if b.kind == "satellite"]
    assert sats, "the example night has an ISS pass"
    target = next(t for t in program.targets if t.is_satellite)
    sat, sf = _skyfield_satellite(eop, target)
    topos = wgs84.latlon(site.lat_deg, site.lon_deg, site.height_m)
    t0 = sf.ts.from_datetime(_dt(plan.start_us))
    t1 = sf.ts.from_datetime(_dt(plan.end_us))
    times, kinds = sat.find_events(topos, t0, t1, altitude_degrees=target.min_el_deg)
    rises = [times[i].utc_datetime().timestamp() for i in range(len(kinds)) if kinds[i] == 0]
    sets = [times[i].utc_datetime().timestamp() for i in range(len(kinds)) if kinds[i] == 2]
    for block in sats:
        # inside one of skyfield's passes above min_el (refraction lifts ours by ~2.6')
        assert any(r - 5 <= block.start_us / 1e6 and block.end_us / 1e6 <= s + 5
                   for r, s in zip(rises, sets, strict=False)), block
        t_us = _every_second(block)
        ts = sf.ts.from_datetimes([_dt(t) for t in t_us])
        alt, _, _ = (sat - topos).at(ts).altaz(temperature_C=site.temperature_c,
                                               pressure_mbar=site.pressure_hpa)
        assert alt.degrees.min() >= target.min_el_deg - 0.01
        assert sat.at(ts).is_sunlit(sf.ephemeris).all()
        assert _sun_alt_deg(sf, topos, ts).max() <= target.sun_max_el_deg + 0.02
        assert _moon_sep_deg(sat, sf, topos, ts).min() >= target.moon_min_sep_deg - 0.02
        # the block is the whole part that meets every constraint: two seconds beyond
        # each end (inside the night), one of them fails there
        for edge_us in (block.start_us - 2_000_000, block.end_us + 2_000_000):
            if not plan.start_us <= edge_us <= plan.end_us:
                continue
            e = sf.ts.from_datetimes([_dt(edge_us)])
            e_alt = (sat - topos).at(e).altaz(temperature_C=site.temperature_c,
                                              pressure_mbar=site.pressure_hpa)[0].degrees[0]
            holds = (e_alt >= target.min_el_deg and sat.at(e).is_sunlit(sf.ephemeris)[0]
                     and _sun_alt_deg(sf, topos, e)[0] <= target.sun_max_el_deg
                     and _moon_sep_deg(sat, sf, topos, e)[0] >= target.moon_min_sep_deg)
            assert not holds, (block, edge_us)


def _sun_alt_deg(sf, topos, ts) -> np.ndarray:
    return (sf.ephemeris["earth"] + topos).at(ts).observe(sf.ephemeris["sun"]) \
        .apparent().altaz()[0].degrees


def _moon_sep_deg(sat, sf, topos, ts) -> np.ndarray:
    """The satellite's distance from the Moon as the site sees them (degrees)."""
    moon = (sf.ephemeris["earth"] + topos).at(ts).observe(sf.ephemeris["moon"]).apparent()
    return (sat - topos).at(ts).separation_from(moon).degrees


def _dt(t_us: int):
    from datetime import UTC, datetime

    return datetime.fromtimestamp(int(t_us) / 1e6, tz=UTC)


def _trapezoid_s(distance_deg: float, rate: float, accel: float) -> float:
    d = abs(distance_deg)
    if d <= rate * rate / accel:
        return 2.0 * math.sqrt(d / accel)
    return d / rate + rate / accel


def test_blocks_never_overlap_and_the_gaps_hold_the_slew_and_setup(example):
    _, plan = example
    lim = EMULATOR_LIMITS
    for a, b in zip(plan.blocks, plan.blocks[1:], strict=False):
        d_az = (b.start_az_deg - a.end_az_deg + 180.0) % 360.0 - 180.0
        shortest = max(_trapezoid_s(d_az, lim.az_max_rate_deg_s, lim.az_max_accel_deg_s2),
                       _trapezoid_s(b.start_el_deg - a.end_el_deg, lim.el_max_rate_deg_s,
                                    lim.el_max_accel_deg_s2))
        assert b.slew_s >= shortest - 0.01, (a.target, b.target)
        assert (b.start_us - a.end_us) / 1e6 >= b.slew_s + plan.setup_s - 0.01, (a, b)


def test_the_cable_wrap_makes_a_slew_go_the_long_way_round():
    # a wrap of exactly one turn, 0..360: from az 340 to az 20 the mount must turn 320°
    limits = MountLimits(wrap_min_deg=0.0, wrap_max_deg=360.0, az_max_rate_deg_s=6.0,
                         el_max_rate_deg_s=6.0, az_max_accel_deg_s2=3.0,
                         el_max_accel_deg_s2=3.0)
    a = Block("A", "radec", 1, 1.0, 0, 600_000_000, 330.0, 40.0, 340.0, 40.0,
              az_travel_deg=10.0)
    b = Block("B", "radec", 1, 1.0, 700_000_000, 1_300_000_000, 20.0, 40.0, 25.0, 40.0,
              az_travel_deg=5.0)
    (_, a0, a1), (slew, b0, _) = mount_chain([a, b], limits, start_place_deg=(330.0, 40.0))
    assert (a0, a1) == pytest.approx((330.0, 340.0))
    assert b0 == pytest.approx(20.0)
    assert slew == pytest.approx(_trapezoid_s(320.0, 6.0, 3.0), abs=1e-6)
    # with the default ±270° wrap the same move is 40° the short way
    wide = MountLimits(az_max_rate_deg_s=6.0, el_max_rate_deg_s=6.0, az_max_accel_deg_s2=3.0,
                       el_max_accel_deg_s2=3.0)
    (_, _, _), (slew, b0, _) = mount_chain([a, b], wide, start_place_deg=(330.0, 40.0))
    assert slew == pytest.approx(_trapezoid_s(40.0, 6.0, 3.0), abs=1e-6)


def test_the_same_program_gives_the_same_plan(example, eop, site):
    program, plan = example
    again = plan_program(PlanRequest(program, plan.start_us, plan.end_us, site), eop)
    assert again.as_dict() == plan.as_dict()
    assert Plan.from_dict(plan.as_dict()).as_dict() == plan.as_dict()


def test_left_out_targets_name_the_constraint_that_never_holds(example):
    _, plan = example
    reasons = {x["target"]: x["reason"] for x in plan.left_out}
    assert "never with the Sun below -18°" in reasons["Altair"]
    assert "above 30°" in reasons["Jupiter"]
    planned = {b.target for b in plan.blocks}
    assert planned.isdisjoint({"Altair", "Jupiter"})
    assert [b.repeat for b in plan.blocks if b.target == "Vega"] == [1, 2]
    vega = [b for b in plan.blocks if b.target == "Vega"]
    assert vega[1].start_us - vega[0].start_us >= 3600e6  # cadence


def test_a_lower_priority_target_left_out_names_the_block_that_took_its_time(tmp_path, eop,
                                                                             site):
    # two targets that can only be observed in the same 15-minute window, 10 minutes each
    prog = tmp_path / "p.toml"
    prog.write_text("""
[defaults]
duration_s = 600
window = ["2024-05-18T22:00:00Z", "2024-05-18T22:15:00Z"]
[[target]]
star = "Deneb"
priority = 1
[[target]]
star = "Vega"
priority = 4
""")
    start_us, end_us = night_window("2024-05-18", site, eop)
    plan = plan_program(PlanRequest(load_program(prog), start_us, end_us, site), eop)
    assert [b.target for b in plan.blocks] == ["Vega"]
    (left,) = plan.left_out
    assert left["target"] == "Deneb" and "taken by Vega" in left["reason"]


def test_skip_leaves_out_targets_already_done(example, eop, site):
    program, plan = example
    rest = plan_program(PlanRequest(program, plan.start_us, plan.end_us, site,
                                    skip=frozenset({"Vega"})), eop)
    assert "Vega" not in {b.target for b in rest.blocks}
    assert {b.target for b in rest.blocks} >= {"Arcturus", "M13"}
