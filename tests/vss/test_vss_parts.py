"""The pure parts of the VSS: error statistics, run-up, pass planning, mapping, messages."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from error_windows import stats_by_plain_python

from virtualstar.astro import MountLimits, Satellite, Site, UtcTimes, observe_mount_times
from virtualstar.server import (
    MappingError,
    Points,
    RampIn,
    TablePath,
    TrackingErrorHistory,
    load_mapping,
    plan_satellite_pass,
)
from virtualstar.server.exceptions import BadRequest
from virtualstar.server.protocol import Request, decode_request, encode


def test_error_statistics_over_any_window_equal_a_direct_computation():
    rng = np.random.default_rng(1)
    t = 1_700_000_000_000_000 + np.arange(50_000, dtype=np.int64) * 1000  # 1 kHz, 50 s
    az, el_err = rng.normal(0, 0.3, t.size), rng.normal(0, 0.2, t.size)
    el = np.radians(rng.uniform(10, 80, t.size))
    h = TrackingErrorHistory()
    for k in range(0, t.size, 997):  # packets of odd sizes straddling the bins
        h.add(t[k:k + 997], az[k:k + 997], el_err[k:k + 997], el[k:k + 997])
    sky = np.hypot(az * np.cos(el), el_err)
    lo, hi = t[0] + 3_000_000, t[0] + 17_000_000  # bin-aligned (0.1 s) window
    sel = (t >= lo) & (t < hi)
    s = h.stats(lo, hi)
    assert s.n == sel.sum()
    assert s.rms_arcsec == pytest.approx(math.sqrt(np.mean(sky[sel] ** 2)), rel=1e-12)
    assert s.peak_arcsec == pytest.approx(sky[sel].max(), rel=1e-12)
    assert s.az_rms_arcsec == pytest.approx(math.sqrt(np.mean((az * np.cos(el))[sel] ** 2)))
    w = h.window(10.0)
    assert w.n == pytest.approx(10_000, abs=200)


def test_compiled_window_figures_equal_the_bins_summed_one_by_one_in_python():
    """`stats` sums the bins compiled (a status asks for three windows): every figure equals,
    to the last bit, the same bins summed in Python, over windows inside, across and outside
    the clock-offset measurements, with and without a followed target."""
    rng = np.random.default_rng(7)
    t0 = 1_700_000_000_000_000
    t = t0 + np.arange(120_000, dtype=np.int64) * 1000  # 1 kHz, 120 s
    az, el_err = rng.normal(0, 0.3, t.size), rng.normal(0, 0.2, t.size)
    el = np.radians(rng.uniform(10, 80, t.size))
    on = np.abs(rng.normal(0, 3.0, t.size))
    on[(t >= t0 + 40_000_000) & (t < t0 + 70_000_000)] = np.nan  # no target: a slew
    dev = np.abs(rng.normal(0, 2.0, t.size))
    h = TrackingErrorHistory()
    for k in range(0, t.size, 1013):
        h.add(t[k:k + 1013], az[k:k + 1013], el_err[k:k + 1013], el[k:k + 1013],
              on[k:k + 1013], np.where(np.isnan(on[k:k + 1013]), np.nan, dev[k:k + 1013]))
    h.note_rates(t[::50], rng.uniform(10.0, 2000.0, t[::50].size))
    for s, off in ((20, 300), (20.05, -300), (35, 0), (50, -1_200), (50.3, 900), (90, 40)):
        h.note_clock_offset(t0 + int(s * 1e6), off)  # equal sizes of both signs: the first
    windows = [(None, None), (t0 + 3_000_000, t0 + 17_000_000), (t0 + 19_950_000, t0 + 20_150_000),
               (t0 + 30_000_000, t0 + 100_000_000), (t0 + 45_000_000, t0 + 65_000_000),
               (t0 + 89_000_000, None), (t0 + 5_000_050, t0 + 5_100_000),
               (t0 + 20_000_000, t0 + 20_100_000)]  # starts in the equal sizes
    windows += [(h.last_t_us - seconds * 1_000_000, None) for seconds in (1, 10, 60)]
    for lo, hi in windows:
        ours = h.stats(lo, hi).as_dict()
        plain = stats_by_plain_python(h, lo, hi)
        assert ours.keys() == plain.keys()
        for key, value in plain.items():
            assert ours[key] == value or (math.isnan(ours[key]) and math.isnan(value)), (
                lo, hi, key, ours[key], value)
    assert h.window(10.0).n == pytest.approx(10_000, abs=100)
    # a history that forgot its oldest bins (kept as a moving view of one array)
    short = TrackingErrorHistory(max_bins=300)
    for k in range(0, t.size, 1013):
        short.add(t[k:k + 1013], az[k:k + 1013], el_err[k:k + 1013], el[k:k + 1013],
                  on[k:k + 1013], dev[k:k + 1013])
    assert short.stats().from_us == int(t[-1]) // 100_000 * 100_000 - 299 * 100_000
    for lo, hi in [(None, None), (t0 + 100_000_000, t0 + 110_000_000), (t0, t0 + 95_000_000)]:
        ours, plain = short.stats(lo, hi).as_dict(), _plain_or_empty(short, lo, hi)
        assert ours.keys() >= plain.keys() and all(
            ours[k] == v or (math.isnan(ours[k]) and math.isnan(v)) for k, v in plain.items())


def _plain_or_empty(h, lo, hi) -> dict:
    """The plain figures, or what `stats` says of a window without samples (n = 0)."""
    if not len(h._select(lo, hi)):
        return {"n": 0}
    return stats_by_plain_python(h, lo, hi)


def test_error_history_keeps_a_bounded_number_of_bins():
    h = TrackingErrorHistory(max_bins=50)
    t = np.arange(0, 20_000_000, 1000, dtype=np.int64)
    h.add(t, np.ones(t.size), np.zeros(t.size), np.zeros(t.size))
    assert h.stats().n == 50 * 100  # the last 50 bins of 0.1 s at 1 kHz
    assert h.series()["t_us"][0] == 15_000_000  # bins 150..199 of 0.1 s


class _Line:
    """A path moving at constant rates: position known exactly."""

    end_us = None

    def __init__(self, p0, v):
        self.p0, self.v = np.asarray(p0), np.asarray(v)

    def sample(self, t_us):
        s = np.asarray(t_us) * 1e-6
        az, el = self.p0[0] + self.v[0] * s, self.p0[1] + self.v[1] * s
        return Points(np.asarray(t_us), az, el, np.full(s.shape, self.v[0]),
                      np.full(s.shape, self.v[1]))


def test_run_up_starts_at_rest_and_meets_the_path_with_its_position_and_rate():
    path = _Line([1.0, 0.5], [0.01, -0.004])
    ramp = RampIn(path, join_us=10_000_000, duration_s=2.0)
    t = np.arange(7_000_000, 12_000_001, 1000, dtype=np.int64)
    p = ramp.sample(t)
    before = t <= ramp.begin_us
    assert np.allclose(p.az_rate_rad_s[before], 0) and np.allclose(p.az_rad[before], ramp.rest_rad[0])
    j = np.searchsorted(t, ramp.join_us)
    exact = path.sample(t[j:j + 1])
    assert p.az_rad[j] == pytest.approx(exact.az_rad[0], abs=1e-15)
    assert p.el_rate_rad_s[j] == pytest.approx(exact.el_rate_rad_s[0], abs=1e-15)
    # continuous position and rate through the join (no step): compare neighbours
    assert np.abs(np.diff(p.az_rad)).max() < 0.01 * 1e-3 * 1.01
    assert np.abs(np.diff(p.el_rate_rad_s)).max() < 1e-5


def test_table_path_returns_its_nodes_exactly():
    t = np.arange(0, 10_000_000, 500_000, dtype=np.int64)
    az, el = np.sin(t * 1e-6), np.cos(t * 1e-6)
    path = TablePath(Points(t, az, el, np.cos(t * 1e-6), -np.sin(t * 1e-6)))
    p = path.sample(t)
    assert np.allclose(p.az_rad, az, atol=1e-14) and np.allclose(p.el_rate_rad_s, -np.sin(t * 1e-6))


def test_a_pass_over_the_zenith_is_rate_and_acceleration_limited_in_azimuth():
    from catalogs import load_tle_file, sample_tle_path

    rec = next(r for r in load_tle_file(sample_tle_path("stations")) if "ISS" in r.name)
    sat = Satellite.from_record(rec)
    site = Site(lat_deg=47.34873, lon_deg=45.17777, pressure_hpa=0.0)  # under the track at 20:00
    mid = int(UtcTimes.from_iso(["2024-05-18T20:00:00Z"]).to_unix_us()[0])
    plan = plan_satellite_pass(sat, site, mid - 60_000_000, mid + 60_000_000, step_s=0.1,
                               limits=MountLimits(), track_rate_limit_deg_s=7.2,
                               accel_limit_deg_s2=3.0)
    assert plan.keyhole_limited and plan.max_el_deg > 88.0
    p = plan.path.points
    rate = np.degrees(p.az_rate_rad_s)
    acc = np.gradient(rate, 0.1)
    assert np.abs(rate).max() <= 7.2 * 1.01
    assert np.abs(acc).max() <= 3.0 * 1.1
    el_acc = np.gradient(np.degrees(p.el_rate_rad_s), 0.1)
    assert np.abs(el_acc).max() <= 3.0 * 1.2  # the cusp at culmination is smoothed too
    obs = observe_mount_times(sat, p.t_us, site)
    far = np.degrees(obs.el_rad) < 60.0  # the 180° azimuth turn spans ~±12 s around culmination
    assert np.allclose(p.el_rad[far], obs.el_rad[far], atol=1e-9)  # exact away from the keyhole
    d_az = np.angle(np.exp(1j * (p.az_rad[far] - obs.az_rad[far])))
    assert np.abs(d_az).max() < 5e-6  # below 1″: plan_keyhole's mid-line, not smoothing
    import erfa

    sep = np.degrees(erfa.seps(p.az_rad, p.el_rad, obs.az_rad, obs.el_rad)) * 3600
    assert sep.max() <= plan.keyhole_max_error_arcsec * (1 + 1e-9)
    lo, hi = math.radians(-270), math.radians(270)
    assert lo <= p.az_rad.min() and p.az_rad.max() <= hi


def test_the_default_mapping_loads_and_a_broken_one_names_what_is_wrong(tmp_path):
    m = load_mapping()
    assert m.signal("az_position") == "axis.az.position" and m.state_codes["fault"] == 6
    doc = json.loads(json.dumps({"signals": dict(m.signals), "functions": dict(m.functions),
                                 "state_codes": m.state_codes}))
    del doc["signals"]["mount_time"]
    doc["functions"]["warp"] = "x.warp"
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    with pytest.raises(MappingError, match="mount_time"):
        load_mapping(bad)
    bad.write_text("{not json")
    with pytest.raises(MappingError, match="not valid JSON"):
        load_mapping(bad)
    with pytest.raises(MappingError, match="cannot read"):
        load_mapping(tmp_path / "missing.json")


def test_messages_round_trip_and_never_carry_nan():
    req = Request(3, "slew", {"star": "Vega"})
    assert decode_request(req.to_json()) == req
    assert json.loads(encode({"x": float("nan"), "y": [np.float64(1.5)]})) == {"x": None, "y": [1.5]}
    with pytest.raises(BadRequest, match="'params' is a list"):
        decode_request('{"id": 1, "cmd": "status", "params": []}')
