"""Apply and invert a model; save and load it; the fitted model predicts an exact mount."""

from __future__ import annotations

import json

import numpy as np
import pytest
from pointing_geometry_truth import ExactMount

from pointing_model import (
    ModelFileError,
    PointingModel,
    PointingRun,
    even_sky_positions,
    fit_run,
    load_model,
    model_from_values,
    wrap_deg_180,
)

ONE_MAS_ARCSEC = 0.001  # the round-trip bound
# The terms are first order: with errors of ~250″ the neglected products reach ~0.2″.
FIRST_ORDER_ARCSEC = 0.25
BIG_MODEL = model_from_values({
    "IA": -292.0, "IE": -213.0, "CA": 91.0, "NPAE": 12.0, "AN": 39.0, "AW": 71.0, "TF": 8.0,
    "TX": -6.9, "ACEC": 5.0, "ACES": -4.0, "ECES": 3.0, "HASA2": 2.5, "HECE8": 1.5,
    "HSCA5CE8": 1.0,
})


def _sky_error_arcsec(az1, el1, az2, el2):
    d_az = np.radians(wrap_deg_180(np.asarray(az1) - az2)) * np.cos(np.radians(el2))
    d_el = np.radians(np.asarray(el1) - el2)
    return np.degrees(np.hypot(d_az, d_el)) * 3600.0


def test_observed_to_encoder_and_back_round_trips_below_a_milliarcsecond():
    az, el = np.meshgrid(np.linspace(0.0, 359.0, 60), np.linspace(5.0, 87.0, 40))
    enc_az, enc_el = BIG_MODEL.observed_to_encoder(az, el)
    back_az, back_el = BIG_MODEL.encoder_to_observed(enc_az, enc_el)
    assert back_az.shape == az.shape
    assert np.max(_sky_error_arcsec(back_az, back_el, az, el)) < ONE_MAS_ARCSEC
    assert np.max(_sky_error_arcsec(enc_az, enc_el, az, el)) > 100.0  # the model did something


def test_scalars_give_scalars():
    enc_az, enc_el = BIG_MODEL.observed_to_encoder(120.0, 45.0)
    assert np.ndim(enc_az) == 0 and np.ndim(enc_el) == 0


def test_model_undefined_at_the_zenith_raises_a_clear_error():
    with pytest.raises(ValueError, match="undefined"):
        BIG_MODEL.observed_to_encoder(10.0, 90.0)
    with pytest.raises(ValueError, match="elevation"):
        BIG_MODEL.observed_to_encoder(10.0, 95.0)


def test_fitted_model_points_an_exact_mount_at_new_stars():
    mount = ExactMount(az_zero=250, el_zero=180, tilt_north=40, tilt_west=-70,
                       el_axis_right_end_up=15, beam_left=90)
    enc_az, enc_el = even_sky_positions(80, min_el_deg=15, max_el_deg=80)
    obs_az, obs_el = mount.observed(enc_az, enc_el)
    model = fit_run(PointingRun(obs_az, obs_el, enc_az, enc_el), "IA,IE,CA,NPAE,AN,AW").model
    new_az, new_el = even_sky_positions(25, min_el_deg=20, max_el_deg=75, rotation_deg=17.0)
    demand_az, demand_el = model.observed_to_encoder(new_az, new_el)
    seen_az, seen_el = mount.observed(demand_az, demand_el)
    raw_error = _sky_error_arcsec(new_az, new_el, *mount.observed(new_az, new_el))
    assert np.min(raw_error) > 100.0
    assert np.max(_sky_error_arcsec(seen_az, seen_el, new_az, new_el)) < FIRST_ORDER_ARCSEC


def test_model_json_round_trip_keeps_terms_values_and_sigmas(tmp_path):
    model = PointingModel(("IA", "HASA2"), (-12.5, 3.25), (0.5, 0.1), {"sky_rms_arcsec": 1.0})
    path = tmp_path / "model.json"
    model.save(path)
    doc = json.loads(path.read_text())
    assert doc["terms"]["IA"] == {"value_arcsec": -12.5, "sigma_arcsec": 0.5}
    loaded = load_model(path)
    assert loaded.terms == model.terms
    assert loaded.values_arcsec == model.values_arcsec
    assert loaded.sigmas_arcsec == model.sigmas_arcsec


@pytest.mark.parametrize(("text", "fragment"), [
    ("{not json", "not JSON"),
    ("[1, 2]", "JSON object"),
    ('{"terms": {"IA": {"value_arcsec": "x"}}}', "finite number"),
    ('{"terms": {"QQ": {"value_arcsec": 1}}}', "QQ"),
    ('{"format": "other", "terms": {}}', "format"),
    ('{"model": 1}', '"terms"'),
])
def test_malformed_model_file_names_the_file_and_the_problem(tmp_path, text, fragment):
    path = tmp_path / "bad.json"
    path.write_text(text)
    with pytest.raises(ModelFileError) as info:
        load_model(path)
    assert str(path) in str(info.value) and fragment in str(info.value)


def test_missing_model_file_is_a_model_file_error(tmp_path):
    with pytest.raises(ModelFileError, match="cannot read"):
        load_model(tmp_path / "absent.json")
