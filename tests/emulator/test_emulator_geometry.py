"""Hidden geometry: the guide camera sees what TPOINT's alt-az formulas predict.

The formulas below are written here independently of mount_emulator.geometry:
observed − encoder = Δ(observed) (TPOINT, A from north through east)
  ΔA = −IA − CA/cosE − NPAE·tanE − AN·sinA·tanE − AW·cosA·tanE
  ΔE = +IE − AN·cosA + AW·sinA − TF·cosE
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from emulator_helpers import holding_mount, ticks
from scipy.optimize import fsolve

from mount_emulator import layout as L
from mount_emulator.exceptions import ConfigError
from mount_emulator.geometry import Geometry, GuideCamera

AS = math.pi / 180 / 3600
TERMS = {"ia": 140.0, "ie": -75.0, "an": 30.0, "aw": -25.0, "npae": 12.0, "ca": 40.0, "tf": 18.0}


def tpoint_delta(t, az, el):
    d_az = (-t["ia"] - t["ca"] / math.cos(el) - t["npae"] * math.tan(el)
            - t["an"] * math.sin(az) * math.tan(el) - t["aw"] * math.cos(az) * math.tan(el))
    d_el = t["ie"] - t["an"] * math.cos(az) + t["aw"] * math.sin(az) - t["tf"] * math.cos(el)
    return d_az * AS, d_el * AS


def expected_offset(t, enc_az, enc_el, star_az, star_el):
    """Where the star appears from the optical axis, solving axis − encoder = Δ(axis)."""
    def eq(x):
        d_az, d_el = tpoint_delta(t, x[0], x[1])
        return [x[0] - d_az - enc_az, x[1] - d_el - enc_el]
    axis_az, axis_el = fsolve(eq, [enc_az, enc_el], xtol=1e-14)
    return (star_az - axis_az) * math.cos(star_el) / AS, (star_el - axis_el) / AS


@pytest.mark.parametrize(("az_deg", "el_deg"), [(10, 20), (100, 45), (200, 70), (300, 80), (45, 5)])
def test_guide_camera_offsets_match_tpoint_formulas_when_pointing_raw(az_deg, el_deg):
    cam = GuideCamera(Geometry(**TERMS), seeing_arcsec=0.0)
    az, el = math.radians(az_deg), math.radians(el_deg)
    dx, dy = cam.offset_arcsec(az, el, az, el)  # encoders on the star's catalogue place
    ex, ey = expected_offset(TERMS, az, el, az, el)
    assert dx == pytest.approx(ex, abs=1e-6)
    assert dy == pytest.approx(ey, abs=1e-6)
    assert math.hypot(dx, dy) > 50.0  # the raw error is large


@pytest.mark.parametrize(("az_deg", "el_deg"), [(30, 30), (250, 60)])
def test_pointing_with_the_tpoint_model_centres_the_star(az_deg, el_deg):
    cam = GuideCamera(Geometry(**TERMS), seeing_arcsec=0.0)
    az, el = math.radians(az_deg), math.radians(el_deg)
    d_az, d_el = tpoint_delta(TERMS, az, el)
    dx, dy = cam.offset_arcsec(az - d_az, el - d_el, az, el)
    assert abs(dx) < 1e-6 and abs(dy) < 1e-6


def test_positive_index_errors_follow_tpoint_definitions():
    # TPOINT: IA > 0 means the azimuth encoder reads IA more than the true azimuth;
    # IE > 0 means the elevation encoder reads IE less than the true elevation.
    az, el = math.radians(123.0), math.radians(40.0)
    enc_az, enc_el = Geometry(ia=100.0).encoder_of_sky(az, el)
    assert (enc_az - az) / AS == pytest.approx(100.0, abs=1e-9)
    enc_az, enc_el = Geometry(ie=100.0).encoder_of_sky(az, el)
    assert (enc_el - el) / AS == pytest.approx(-100.0, abs=1e-9)


def test_guide_camera_sees_the_real_encoders_after_a_slew():
    m = holding_mount()
    star = (math.radians(60.0), math.radians(50.0))
    m.slew(*star)
    m.run(ticks(20.0))
    cam = GuideCamera(Geometry(**TERMS), seeing_arcsec=0.0)
    enc_az, enc_el = m.axis_slot(0, L.A_ENC), m.axis_slot(1, L.A_ENC)
    dx, dy = cam.offset_arcsec(enc_az, enc_el, *star)
    ex, ey = expected_offset(TERMS, enc_az, enc_el, *star)
    assert dx == pytest.approx(ex, abs=1e-6) and dy == pytest.approx(ey, abs=1e-6)


def test_seeing_noise_has_the_requested_spread():
    cam = GuideCamera(Geometry(), seeing_arcsec=0.5, seed=3)
    samples = np.array([cam.offset_arcsec(0.2, 0.8, 0.2, 0.8) for _ in range(4000)])
    assert samples.std(axis=0) == pytest.approx([0.5, 0.5], rel=0.06)
    assert np.abs(samples.mean(axis=0)).max() < 0.03


@pytest.mark.parametrize("seed", [0, 1, 7, 42])
def test_seeded_geometry_is_reproducible_and_has_at_least_100_arcsec_raw_error(seed):
    g = Geometry.from_seed(seed)
    assert g == Geometry.from_seed(seed)
    assert g.raw_rms_arcsec() >= 100.0


def test_geometry_loads_from_toml_and_json(tmp_path):
    toml = tmp_path / "g.toml"
    toml.write_text("[geometry]\nIA = 140.0\nie_arcsec = -75\nTF = 18\n")
    assert Geometry.from_file(toml) == Geometry(ia=140.0, ie=-75.0, tf=18.0)
    js = tmp_path / "g.json"
    js.write_text('{"npae": 12.5, "CA": 40}')
    assert Geometry.from_file(js) == Geometry(npae=12.5, ca=40.0)


def test_geometry_file_with_an_unknown_term_names_the_accepted_ones(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("IX = 3\n")
    with pytest.raises(ConfigError, match="unknown geometry term 'IX'.*IA, IE, AN, AW, NPAE, CA, TF"):
        Geometry.from_file(bad)
