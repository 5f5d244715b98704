"""Fit: AuxTel reference, synthetic recovery, σ calibration (Monte Carlo), LOO, rejection, auto."""

from __future__ import annotations

import numpy as np
import pytest

from pointing_model import (
    FitError,
    PointingRun,
    design_matrix,
    fit_run,
    load_tpoint,
    model_from_values,
    select_terms,
    simulate_run,
)

# TPOINT's published fit of auxtel_20220406.dat (Rubin tstn-014), arcsec.
AUXTEL_TPOINT = {"IA": -292.01, "IE": -213.05, "AN": 39.16, "AW": 70.89, "CA": 90.93, "TX": -6.86}
AUXTEL_TPOINT_SIGMA = {"IA": 2.17, "IE": 0.91, "AN": 0.50, "AW": 0.50}
AUXTEL_SKY_RMS, AUXTEL_PSD = 3.14, 3.33
COEFF_TOL, RMS_TOL = 0.05, 0.02  # the tolerances
PUBLISHED_ROUNDING = 0.01  # TPOINT prints two decimals


def test_auxtel_fit_reproduces_tpoint_published_values(auxtel_path):
    result = fit_run(load_tpoint(auxtel_path), list(AUXTEL_TPOINT))
    values = dict(zip(result.terms, result.values_arcsec, strict=True))
    for term, published in AUXTEL_TPOINT.items():
        assert values[term] == pytest.approx(published, abs=COEFF_TOL), term
    assert result.sky_rms_arcsec == pytest.approx(AUXTEL_SKY_RMS, abs=RMS_TOL)
    assert result.psd_arcsec == pytest.approx(AUXTEL_PSD, abs=RMS_TOL)
    sigmas = dict(zip(result.terms, result.sigmas_arcsec, strict=True))
    for term, published in AUXTEL_TPOINT_SIGMA.items():
        assert sigmas[term] == pytest.approx(published, abs=PUBLISHED_ROUNDING), term
    assert result.raw_sky_rms_arcsec == pytest.approx(250.0, abs=1.0)
    assert (result.n_obs, result.n_rejected) == (54, 0)


def test_auxtel_reports_the_ia_ca_correlation(auxtel_path):
    result = fit_run(load_tpoint(auxtel_path), list(AUXTEL_TPOINT))
    x = design_matrix(result.terms, np.radians(load_tpoint(auxtel_path).obs_az_deg),
                      np.radians(load_tpoint(auxtel_path).obs_el_deg))
    cov = np.linalg.inv(x.T @ x)
    i, j = result.terms.index("IA"), result.terms.index("CA")
    expected = cov[i, j] / np.sqrt(cov[i, i] * cov[j, j])
    assert [(a, b) for a, b, _ in result.high_correlations] == [("IA", "CA")]
    assert result.high_correlations[0][2] == pytest.approx(expected, rel=1e-9)
    assert 1.0 < result.condition_number < 100.0


RICH_TRUTH = {
    "IA": -120.0, "IE": 45.0, "CA": 30.0, "NPAE": -15.0, "AN": 20.0, "AW": -25.0, "TF": 12.0,
    "TX": -4.0, "ACEC": 6.0, "ACES": -5.0, "ECES": 8.0, "HASA2": 3.0, "HECA2": -2.5,
    "HSCA5CE8": 2.0, "HZSE3": 1.5,
}


def test_every_term_is_recovered_within_three_sigma():
    truth = model_from_values(RICH_TRUTH)
    run = simulate_run(truth, 400, 1.0, rng=np.random.default_rng(11), min_el_deg=10,
                       max_el_deg=85)
    result = fit_run(run, list(RICH_TRUTH))
    z = (result.values_arcsec - np.array(list(RICH_TRUTH.values()))) / result.sigmas_stat_arcsec
    assert np.all(np.abs(z) < 3.0), dict(zip(result.terms, np.round(z, 2), strict=True))


MC_TERMS = {"IA": -50.0, "IE": 30.0, "CA": 20.0, "NPAE": 10.0, "AN": 15.0, "AW": -12.0,
            "TF": 5.0, "TX": -3.0, "HASA2": 2.0}
MC_TRIALS, MC_STARS = 200, 60
# The standard deviation of 200 unit-normal draws has a standard error of 1/√400 = 0.05:
# ±0.15 is a 3-standard-error band.
MC_SPREAD_TOL = 0.15


def test_sigma_matches_the_monte_carlo_spread_of_the_fit():
    truth = model_from_values(MC_TERMS)
    true_values = np.array(list(MC_TERMS.values()))
    rng = np.random.default_rng(2024)
    z_stat, z_tpoint = [], []
    for _ in range(MC_TRIALS):
        result = fit_run(simulate_run(truth, MC_STARS, 1.0, rng=rng), list(MC_TERMS))
        err = result.values_arcsec - true_values
        z_stat.append(err / result.sigmas_stat_arcsec)
        z_tpoint.append(err / result.sigmas_arcsec)
    spread_stat = np.std(z_stat, axis=0)
    np.testing.assert_allclose(spread_stat, 1.0, atol=MC_SPREAD_TOL)
    # TPOINT's σ uses the sky RMS over N stars instead of the per-axis SD over 2N − M
    # residuals: it is larger by √((2N − M)/N), so its z spreads as √(N/(2N − M)).
    expected = np.sqrt(MC_STARS / (2 * MC_STARS - len(MC_TERMS)))
    np.testing.assert_allclose(np.std(z_tpoint, axis=0), expected, atol=MC_SPREAD_TOL * expected)
    assert np.all(np.abs(np.mean(z_stat, axis=0)) < 3 / np.sqrt(MC_TRIALS))  # unbiased


def test_leave_one_out_rms_equals_refitting_without_each_star():
    truth = model_from_values({"IA": 20.0, "IE": -10.0, "CA": 5.0, "AN": 3.0, "AW": 4.0})
    run = simulate_run(truth, 30, 2.0, rng=np.random.default_rng(5))
    terms = ["IA", "IE", "CA", "AN", "AW"]
    closed_form = fit_run(run, terms).loo_rms_arcsec
    squares = []
    for i in range(len(run)):
        keep = np.arange(len(run)) != i
        model = fit_run(run.subset(keep), terms).model
        pred_s, pred_e = model.offsets_rad(np.radians(run.obs_az_deg[i]),
                                           np.radians(run.obs_el_deg[i]))
        res_s, res_e = run.subset(~keep).residuals_rad()
        squares.append(((res_s - pred_s) ** 2 + (res_e - pred_e) ** 2)[0])
    brute_force = np.sqrt(np.mean(squares)) * 206264.80624709636
    assert closed_form == pytest.approx(brute_force, rel=1e-9)


def _run_with_outliers():
    truth = model_from_values({"IA": 60.0, "IE": -40.0, "CA": 10.0, "AN": 8.0, "AW": -6.0})
    run = simulate_run(truth, 60, 1.0, rng=np.random.default_rng(8))
    enc_el = run.enc_el_deg.copy()
    enc_el[[7, 33]] += 40.0 / 3600.0  # two 40″ blunders
    return PointingRun(run.obs_az_deg, run.obs_el_deg, run.enc_az_deg, enc_el,
                       line_numbers=tuple(range(10, 70)))


def test_reject_sigma_removes_exactly_the_blunders():
    result = fit_run(_run_with_outliers(), "IA,IE,CA,AN,AW", reject_sigma=3.0)
    assert list(np.flatnonzero(~result.used)) == [7, 33]
    assert result.to_json_dict()["rejected_lines"] == [17, 43]
    assert result.n_rejected == 2 and result.n_obs == 58
    assert result.sky_rms_arcsec < 2.0


def test_no_rejection_unless_asked():
    result = fit_run(_run_with_outliers(), "IA,IE,CA,AN,AW")
    assert result.n_rejected == 0 and result.sky_rms_arcsec > 5.0


def test_auto_selection_finds_the_terms_present_and_no_others():
    true_terms = {"IA": -80.0, "IE": 25.0, "CA": 15.0, "AN": 12.0, "AW": -9.0, "TF": 10.0,
                  "HASA2": 6.0}
    run = simulate_run(model_from_values(true_terms), 150, 1.0, rng=np.random.default_rng(3),
                       min_el_deg=15)
    result = select_terms(run)
    assert set(result.terms) == set(true_terms)
    assert result.selection[-1].accepted is False  # it stopped on a non-significant term


def test_raw_azimuth_wrapped_differently_gives_the_same_fit():
    run = simulate_run(model_from_values({"IA": 30.0, "IE": 5.0}), 40, 1.0,
                       rng=np.random.default_rng(1))
    shifted = PointingRun(run.obs_az_deg, run.obs_el_deg, run.enc_az_deg - 360.0, run.enc_el_deg)
    a, b = fit_run(run, "IA,IE"), fit_run(shifted, "IA,IE")
    np.testing.assert_allclose(a.values_arcsec, b.values_arcsec, atol=1e-9)
    assert b.sky_rms_arcsec < 3.0


def test_degenerate_terms_are_named_in_the_error():
    run = simulate_run(model_from_values({"IA": 1.0}), 30, 1.0, rng=np.random.default_rng(0))
    with pytest.raises(FitError, match="TF.*ECEC|ECEC.*TF"):
        fit_run(run, "IA,IE,TF,ECEC")


def test_too_few_observations_for_the_terms_is_a_fit_error():
    run = simulate_run(model_from_values({"IA": 1.0}), 3, 1.0, rng=np.random.default_rng(0))
    with pytest.raises(FitError, match="3 observations cannot determine 6 terms"):
        fit_run(run, "IA,IE,CA,NPAE,AN,AW")


def test_noise_free_data_fit_exactly_and_json_stays_valid():
    import json

    run = simulate_run(model_from_values({"IA": 30.0, "IE": -20.0}), 7, 0.0,
                       rng=np.random.default_rng(0))
    result = fit_run(run, "IA,IE,CA,NPAE,AN,AW")  # N = M + 1: every star has leverage
    np.testing.assert_allclose(result.values_arcsec, [30, -20, 0, 0, 0, 0], atol=1e-6)
    assert result.sky_rms_arcsec < 1e-6
    json.loads(json.dumps(result.to_json_dict(), allow_nan=False))
    auto = select_terms(run)
    json.loads(json.dumps(auto.to_json_dict(), allow_nan=False))


def test_auto_selection_stops_when_noise_free_data_are_fitted_exactly():
    run = simulate_run(model_from_values({"IA": 30.0, "IE": -20.0, "CA": 5.0}), 40, 0.0,
                       rng=np.random.default_rng(0))
    assert select_terms(run).terms == ("IA", "IE", "CA")
