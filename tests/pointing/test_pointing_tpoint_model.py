"""TPOINT's model files and harmonic conventions, checked against TPOINT's own fit of a real run."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest
from typer.testing import CliRunner

from pointing_model import fit_run, load_model, load_tpoint
from pointing_model.cli import app
from pointing_model.exceptions import ModelFileError
from pointing_model.tpoint_model_file import read_tpoint_model, write_tpoint_model

runner = CliRunner()
# TPOINT applies its terms rigorously, we linearly: coefficients agree to a small part of σ
# (largest seen: AW, 0.25σ = 0.05″). A sign error would miss by 2|value|, ≥ 4σ for every harmonic.
AGREEMENT_IN_SIGMA = 0.3
SKY_RMS_REL_TOLERANCE = 0.01


def test_tpoint_model_file_is_read_with_its_markers(auxtel_fauto_path):
    model = load_model(auxtel_fauto_path, substitute={"TX10": "TX"})
    assert len(model.terms) == 17
    assert model.fit_info["n_obs"] == 53
    assert model.fit_info["sky_rms_arcsec"] == pytest.approx(1.3005)
    assert model.fit_info["fixed"] == ["IE", "NPAE"]
    assert model.fit_info["substituted"] == {"TX": "TX10"}
    assert sum(name.startswith("H") for name in model.terms) == 9
    assert model.as_dict()["IA"] == pytest.approx(-291.2637)


def test_our_fit_equals_tpoints_automatic_fit_sign_for_sign(auxtel_path, auxtel_fauto_path):
    tpoint = load_model(auxtel_fauto_path, substitute={"TX10": "TX"})
    fixed = set(tpoint.fit_info["fixed"])
    assert all(v == 0.0 for n, v in tpoint.as_dict().items() if n in fixed)
    free = [n for n in tpoint.terms if n not in fixed]
    # TPOINT's fit used 53 of 54 records: the one a 3-sigma rejection drops
    ours = fit_run(load_tpoint(auxtel_path), free, reject_sigma=3.0)
    assert ours.n_obs == tpoint.fit_info["n_obs"]
    theirs = dict(zip(tpoint.terms, zip(tpoint.values_arcsec, tpoint.sigmas_arcsec,
                                        strict=True), strict=True))
    for name, value in zip(ours.terms, ours.values_arcsec, strict=True):
        t_value, t_sigma = theirs[name]
        assert np.sign(value) == np.sign(t_value), f"{name}: ours {value:+.4f}, TPOINT {t_value:+.4f}"
        assert abs(value - t_value) <= AGREEMENT_IN_SIGMA * t_sigma, (name, value, t_value, t_sigma)
    assert ours.sky_rms_arcsec == pytest.approx(tpoint.fit_info["sky_rms_arcsec"],
                                                rel=SKY_RMS_REL_TOLERANCE)


def test_tpoint_model_round_trips_through_its_own_layout(auxtel_fauto_path):
    model = load_model(auxtel_fauto_path, substitute={"TX10": "TX"})
    out = io.StringIO()
    write_tpoint_model(model, out)
    text = out.getvalue()
    assert " =IE " in text and "& HASA2 " in text and "  TX10 " in text  # TPOINT's own names
    again = read_tpoint_model(text.splitlines(), "<round trip>", substitute={"TX10": "TX"})
    assert again.terms == model.terms
    np.testing.assert_allclose(again.values_arcsec, model.values_arcsec, atol=5e-5)
    assert again.fit_info["fixed"] == model.fit_info["fixed"]


def test_a_term_we_do_not_implement_is_refused_by_name(auxtel_fauto_path, tmp_path):
    with pytest.raises(ModelFileError, match=r"fauto.mod:19: .*'TX10'.*--substitute TX10=TX"):
        load_model(auxtel_fauto_path)
    rotator = tmp_path / "rot.mod"
    rotator.write_text("Nasmyth\nT 10 1.0 0 0\n  IA  +10.0  1.0\n  NRX  +3.0  1.0\nEND\n")
    with pytest.raises(ModelFileError, match=r"rot.mod:4: .*'NRX'.*rotator"):
        load_model(rotator)


@pytest.mark.parametrize(("text", "fragment"), [
    ("caption only\n", "T line"),
    ("C\nX 10 1\nEND\n", "T N_OBS SKY_RMS"),
    ("C\nT 10 1.0\n  IA  abc\nEND\n", "must be numbers"),
    ("C\nT 10 1.0\n  IA  1.0 2.0 3.0\nEND\n", "term line"),
    ("C\nT 10 1.0\n  IA  1.0\n", "no END"),
    ("C\nT 10 1.0\n  IA  1.0\n  IA  2.0\nEND\n", "twice"),
])
def test_malformed_tpoint_model_names_the_line(tmp_path, text, fragment):
    path = tmp_path / "bad.mod"
    path.write_text(text)
    with pytest.raises(ModelFileError, match=fragment):
        read_tpoint_model(text.splitlines(), str(path))


def test_fit_writes_a_tpoint_model_that_apply_reads(auxtel_path, tmp_path):
    mod, js = tmp_path / "fit.mod", tmp_path / "fit.json"
    for out in (mod, js):
        result = runner.invoke(app, ["fit", str(auxtel_path), "--terms", "IA,IE,AN,AW,CA,TX,HESA2",
                                     "-o", str(out)])
        assert result.exit_code == 0, result.output
    assert mod.read_text().splitlines()[1].split()[:2] == ["T", "54"]
    answers = []
    for path in (mod, js):
        result = runner.invoke(app, ["apply", str(path), "--altaz", "120 45", "--json"])
        assert result.exit_code == 0, result.output
        answers.append(json.loads(result.stdout))
    # the .mod keeps 4 decimals of an arcsecond: 1e-4″ ≈ 3e-8°
    assert answers[0]["encoder_az_deg"] == pytest.approx(answers[1]["encoder_az_deg"], abs=1e-7)
    assert answers[0]["encoder_el_deg"] == pytest.approx(answers[1]["encoder_el_deg"], abs=1e-7)


def test_masked_records_are_skipped_and_counted_in_the_fit_report(auxtel_path, tmp_path):
    lines = auxtel_path.read_text().splitlines()
    first = next(i for i, ln in enumerate(lines) if ln[:1].isdigit())
    masked = sorted([first + k for k in range(0, 54, 2)] + [first + 1, first + 3, first + 5])
    for i in masked:
        lines[i] = ";" + lines[i]
    path = tmp_path / "masked.dat"
    path.write_text("\n".join(lines) + "\n")
    run = load_tpoint(path)
    full = load_tpoint(auxtel_path)
    assert len(run) == len(full) - 30
    assert run.masked_lines == tuple(i + 1 for i in masked)
    keep = np.ones(len(full), dtype=bool)
    keep[[i - first for i in masked]] = False
    np.testing.assert_array_equal(run.obs_az_deg, full.obs_az_deg[keep])
    result = runner.invoke(app, ["fit", str(path), "--terms", "IA,IE,AN,AW,CA,TX", "--json"])
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    assert doc["n_masked"] == 30 and doc["n_obs"] == len(full) - 30
    text = runner.invoke(app, ["fit", str(path), "--terms", "IA,IE,AN,AW,CA,TX"]).output
    assert "30 masked with ';'" in text
