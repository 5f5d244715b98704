"""The pointing-model CLI through Typer's CliRunner: fit --json, simulate → fit, apply, errors."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from pointing_model import fit_run, load_model, load_tpoint
from pointing_model.cli import app

runner = CliRunner()
CONTRACT_FIELDS = {"terms", "sky_rms_arcsec", "psd_arcsec", "n_obs", "n_rejected"}


def test_fit_json_has_the_contract_fields_and_the_library_numbers(auxtel_path):
    result = runner.invoke(app, ["fit", str(auxtel_path), "--terms", "IA,IE,AN,AW,CA,TX",
                                 "--json"])
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    assert set(doc) >= CONTRACT_FIELDS
    assert list(doc["terms"]) == ["IA", "IE", "AN", "AW", "CA", "TX"]
    lib = fit_run(load_tpoint(auxtel_path), "IA,IE,AN,AW,CA,TX")
    for name, value, sigma in zip(lib.terms, lib.values_arcsec, lib.sigmas_arcsec, strict=True):
        assert doc["terms"][name]["value_arcsec"] == pytest.approx(value, rel=1e-12)
        assert doc["terms"][name]["sigma_arcsec"] == pytest.approx(sigma, rel=1e-12)
    assert doc["sky_rms_arcsec"] == pytest.approx(3.14, abs=0.02)
    assert doc["psd_arcsec"] == pytest.approx(3.33, abs=0.02)
    assert (doc["n_obs"], doc["n_rejected"]) == (54, 0)


def test_simulate_then_fit_recovers_the_model_and_writes_model_and_plot(tmp_path):
    truth = {"IA": -200.0, "IE": 150.0, "CA": 40.0, "AN": 25.0, "AW": -30.0, "TF": 10.0}
    run_path, model_path, png = tmp_path / "run.dat", tmp_path / "m.json", tmp_path / "r.png"
    inline = ",".join(f"{k}={v}" for k, v in truth.items())
    sim = runner.invoke(app, ["simulate", "--model", inline, "--stars", "80", "--noise", "1.0",
                              "-o", str(run_path), "--seed", "7"])
    assert sim.exit_code == 0, sim.output
    fit = runner.invoke(app, ["fit", str(run_path), "--terms", ",".join(truth), "-o",
                              str(model_path), "--plot", str(png), "--json"])
    assert fit.exit_code == 0, fit.output
    doc = json.loads(fit.stdout)
    for name, true_value in truth.items():
        entry = doc["terms"][name]
        assert abs(entry["value_arcsec"] - true_value) < 3 * entry["sigma_arcsec"], name
    assert load_model(model_path).terms == tuple(truth)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000


def test_simulate_with_the_same_seed_writes_the_same_file(tmp_path):
    args = ["simulate", "--model", "IA=10,IE=5", "--stars", "5", "--noise", "1", "--seed", "3"]
    assert runner.invoke(app, args).stdout == runner.invoke(app, args).stdout


def test_apply_prints_the_encoder_demand_of_the_model(tmp_path):
    model_path = tmp_path / "m.json"
    run = runner.invoke(app, ["simulate", "--model", "IA=-100,IE=50,CA=20", "--stars", "30",
                              "--noise", "0.5", "--seed", "1", "-o", str(tmp_path / "r.dat")])
    assert run.exit_code == 0
    assert runner.invoke(app, ["fit", str(tmp_path / "r.dat"), "--terms", "IA,IE,CA",
                               "-o", str(model_path)]).exit_code == 0
    out = runner.invoke(app, ["apply", str(model_path), "--altaz", "120 45", "--json"])
    assert out.exit_code == 0, out.output
    doc = json.loads(out.stdout)
    enc_az, enc_el = load_model(model_path).observed_to_encoder(120.0, 45.0)
    assert doc["encoder_az_deg"] == pytest.approx(float(enc_az), abs=1e-12)
    assert doc["encoder_el_deg"] == pytest.approx(float(enc_el), abs=1e-12)
    back = runner.invoke(app, ["apply", str(model_path), "--inverse", "--json", "--altaz",
                               f"{doc['encoder_az_deg']} {doc['encoder_el_deg']}"])
    assert json.loads(back.stdout)["observed_az_deg"] == pytest.approx(120.0, abs=1e-9)
    text = runner.invoke(app, ["apply", str(model_path), "--altaz", "120 45"])
    assert text.stdout.startswith("encoder az ")


def test_fit_auto_prints_the_selection_steps(tmp_path):
    path = tmp_path / "r.dat"
    runner.invoke(app, ["simulate", "--model", "IA=-80,IE=25,AN=12,AW=-9", "--stars", "60",
                        "--noise", "1", "--seed", "4", "-o", str(path)])
    out = runner.invoke(app, ["fit", str(path), "--auto"])
    assert out.exit_code == 0, out.output
    assert "auto:" in out.stdout and "stopped" in out.stdout


@pytest.mark.parametrize(("args", "code", "fragment"), [
    (["fit", "{missing}"], 2, "No such file"),  # a file named on the command line: an argument
    (["fit", "{bad}"], 1, "bad.dat:4"),
    (["fit", "{good}", "--terms", "IA,FOO"], 2, "unknown pointing term 'FOO'"),
    (["fit", "{good}", "--terms", "IA", "--auto"], 2, "either --terms or --auto"),
    (["fit", "{good}", "--terms", "IA,IE,TF,ECEC"], 1, "cannot be told apart"),
    (["apply", "{model}", "--altaz", "abc"], 2, "expected two numbers"),
    (["apply", "{model}", "--altaz", "10 95"], 2, "elevation"),
    (["apply", "{bad}", "--altaz", "10 45"], 1, "not JSON"),
    (["simulate", "--model", "IA:3", "--stars", "3", "--noise", "1"], 1, "IA:3"),
    (["simulate", "--model", "IA=x", "--stars", "3", "--noise", "1"], 2, "NAME=ARCSEC"),
])
def test_bad_arguments_and_files_exit_non_zero_with_a_message(tmp_path, args, code, fragment):
    good = tmp_path / "good.dat"
    good.write_text("C\n: ALTAZ\n+10 0 0\n" + "".join(
        f"{az} {el} {az + 0.01} {el + 0.01}\n" for az, el in zip(range(0, 360, 30),
                                                                  np.linspace(20, 80, 12), strict=True)))
    (tmp_path / "bad.dat").write_text("C\n: ALTAZ\n+10 0 0\n1 2 3\n")
    model = tmp_path / "m.json"
    model.write_text('{"terms": {"IA": {"value_arcsec": 1.0}}}')
    paths = {"missing": tmp_path / "none.dat", "bad": tmp_path / "bad.dat", "good": good,
             "model": model}
    result = runner.invoke(app, [a.format(**paths) for a in args])
    assert result.exit_code == code, result.output
    assert fragment in result.output


def test_fit_substitute_fits_a_tpoint_term_as_ours_and_names_it_back(tmp_path):
    """TX10 is TPOINT's, not ours: --substitute TX10=TX fits TX (the message that suggests
    it now holds for fit too) and the .mod written names the term TX10 again."""
    run_path, mod = tmp_path / "run.dat", tmp_path / "m.mod"
    runner.invoke(app, ["simulate", "--model", "IA=-120,IE=40,TX=12", "--stars", "60",
                        "--noise", "0.5", "--seed", "5", "-o", str(run_path)])
    refused = runner.invoke(app, ["fit", str(run_path), "--terms", "IA,IE,TX10"])
    assert refused.exit_code == 2 and "--substitute TX10=TX" in refused.output
    result = runner.invoke(app, ["fit", str(run_path), "--terms", "IA,IE,TX10", "--substitute",
                                 "TX10=TX", "-o", str(mod), "--json"])
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    lib = fit_run(load_tpoint(run_path), "IA,IE,TX")
    assert doc["terms"]["TX"]["value_arcsec"] == pytest.approx(lib.values_arcsec[2], rel=1e-12)
    assert abs(doc["terms"]["TX"]["value_arcsec"] - 12.0) < 3 * doc["terms"]["TX"]["sigma_arcsec"]
    assert doc["substituted"] == {"TX": "TX10"}
    assert any(line.split()[:1] == ["TX10"] for line in mod.read_text().splitlines())
    again = load_model(mod, substitute={"TX10": "TX"})
    assert again.terms == ("IA", "IE", "TX")
    assert again.values_arcsec[2] == pytest.approx(lib.values_arcsec[2], abs=1e-4)
    text = runner.invoke(app, ["fit", str(run_path), "--terms", "IA,IE,TX10", "--substitute",
                               "TX10=TX"])
    assert "TX10 fitted as TX" in text.stdout
    stray = runner.invoke(app, ["fit", str(run_path), "--terms", "IA,IE", "--substitute",
                                "TX10=TX"])
    assert stray.exit_code == 2 and "not among --terms" in stray.output


def test_fit_substitute_on_the_auxtel_run_gives_tpoints_tx10(auxtel_path, auxtel_fauto_path):
    """TPOINT's own fit of the run names TX10 11.92″; ours, with TX for TX10 and the other
    terms it chose, lands within its σ."""
    theirs = load_model(auxtel_fauto_path, substitute={"TX10": "TX"})
    free = [t for t in theirs.terms if t not in theirs.fit_info.get("fixed", ())]
    named = ",".join("TX10" if t == "TX" else t for t in free)
    result = runner.invoke(app, ["fit", str(auxtel_path), "--terms", named, "--substitute",
                                 "TX10=TX", "--json"])
    assert result.exit_code == 0, result.output
    tx = json.loads(result.stdout)["terms"]["TX"]
    assert abs(tx["value_arcsec"] - 11.9248) < tx["sigma_arcsec"]


def test_simulate_writes_the_bundled_sites_latitude_unless_told(tmp_path, monkeypatch):
    from virtualstar.astro import load_site

    monkeypatch.delenv("VIRTUALSTAR_SITE", raising=False)
    args = ["simulate", "--model", "IA=10", "--stars", "3", "--noise", "1", "--seed", "1"]
    for extra, expected in (([], load_site().lat_deg), (["--latitude-deg", "-30.2446"],
                                                       -30.2446)):
        out = tmp_path / "r.dat"
        assert runner.invoke(app, [*args, *extra, "-o", str(out)]).exit_code == 0
        assert load_tpoint(out).parameters.latitude_deg == pytest.approx(expected, abs=1e-3)
    site = tmp_path / "site.toml"
    site.write_text("[site]\nname = 'La Silla'\nlat_deg = -29.2567\nlon_deg = -70.73\n"
                    "height_m = 2400\n")
    monkeypatch.setenv("VIRTUALSTAR_SITE", str(site))
    out = tmp_path / "r2.dat"
    assert runner.invoke(app, [*args, "-o", str(out)]).exit_code == 0
    assert load_tpoint(out).parameters.latitude_deg == pytest.approx(-29.2567, abs=1e-3)
