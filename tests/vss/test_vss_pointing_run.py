"""End to end: measure a pointing run on the emulator through the VSS, fit it, load it.

The emulator hides a TPOINT geometry (read from tests/vss/data/hidden-geometry.toml)
and its guide camera adds Gaussian noise of SEEING_ARCSEC per axis. The independent
truth is that file: `vs pointing-run` + `pointing-model fit` must recover each term
within 4 σ_stat (the fit's statistical standard error, the σ whose Monte Carlo spread
is 1 — docs/pointing-model.md), and with the fitted model loaded the camera must see
new stars within about twice the noise of the optical axis.
"""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner
from vss_rig import Rig

from mount_emulator import Geometry
from pointing_model import load_tpoint
from pointing_model.cli import app as pm_app
from virtualstar.astro import UtcTimes, load_site
from virtualstar.cli.main import app
from virtualstar.server import build_server
from virtualstar.vss_client import VssRequestError, call_server

runner = CliRunner()
GEOMETRY_FILE = Path(__file__).parent / "data" / "hidden-geometry.toml"
SEEING_ARCSEC = 0.5  # guide-camera noise, 1 σ per axis
SKY_NOISE_ARCSEC = math.sqrt(2) * SEEING_ARCSEC  # RMS length of a pure-noise offset
TERMS = "IA,IE,AN,AW,NPAE,CA,TF"
START = "2024-05-18T21:30:00Z"  # Poznań, dusk
SPEED = 200.0  # lockstep, paced: mount seconds per wall second at most


@pytest.fixture(scope="module")
def hidden():
    truth = {k.upper(): float(v) for k, v in
             tomllib.loads(GEOMETRY_FILE.read_text())["geometry"].items()}
    start_us = int(UtcTimes.from_iso([START]).to_unix_us()[0])
    rig = Rig(start_us=start_us, site=load_site(), pace=SPEED,
              emulator_options={"geometry_arcsec": {k.lower(): v for k, v in truth.items()},
                                "seeing_arcsec": SEEING_ARCSEC}).start()
    yield rig, truth
    rig.close()


def vs(*args: str) -> dict:
    res = runner.invoke(app, [*args, "--json"])
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout)


def test_pointing_run_fit_recovers_the_hidden_geometry_and_the_loaded_model_centres_new_stars(
        hidden, tmp_path):
    rig, truth = hidden
    assert Geometry.from_file(GEOMETRY_FILE).raw_rms_arcsec() >= 100.0  # the goal's premise
    run_file = tmp_path / "run.dat"
    run = vs("pointing-run", "--stars", "20", "-o", str(run_file), "--server", rig.url)
    assert run["n_obs"] >= 18, run["skipped"]
    assert run["raw_sky_rms_arcsec"] >= 100.0
    # the file is TPOINT input: observed − raw is the hidden error, not the offset's double
    data = load_tpoint(run_file)
    assert len(data) == run["n_obs"]
    assert data.raw_sky_rms_arcsec() == pytest.approx(run["raw_sky_rms_arcsec"], rel=0.05)

    model_file = tmp_path / "model.json"
    res = runner.invoke(pm_app, ["fit", str(run_file), "--terms", TERMS, "-o", str(model_file),
                                 "--json"])
    assert res.exit_code == 0, res.output
    fit = json.loads(res.stdout)
    for term, value in truth.items():
        got = fit["terms"][term]
        pull = (got["value_arcsec"] - value) / got["sigma_stat_arcsec"]
        assert abs(pull) < 4.0, (term, value, got)
    # what is left is the camera noise
    assert fit["sky_rms_arcsec"] < 1.5 * SKY_NOISE_ARCSEC

    loaded = vs("model", "load", str(model_file), "--server", rig.url)
    assert loaded["pointing_model"] == str(model_file.resolve())
    again = vs("pointing-run", "--stars", "8", "--min-el", "30", "-o", str(tmp_path / "new.dat"),
               "--server", rig.url)
    offsets = np.array([s["offset_arcsec"]["total"] for s in again["samples"]])
    assert again["n_obs"] >= 6 and all(s["pointing_model"] for s in again["samples"])
    assert np.sqrt(np.mean(offsets**2)) < 2.0 * SKY_NOISE_ARCSEC, offsets
    # the raw readings do not depend on the model: the new run fits to the same geometry
    assert load_tpoint(tmp_path / "new.dat").raw_sky_rms_arcsec() > 100.0
    assert vs("model", "unload", "--server", rig.url)["pointing_model"] is None


def test_pointing_sample_on_a_mount_without_guide_camera_says_what_is_missing(hidden, tmp_path):
    rig, _ = hidden
    mapping = json.loads((Path(__file__).parents[2] / "virtualstar" / "data" /
                          "emulator-mapping.json").read_text())
    del mapping["functions"]["guide_measure"]
    path = tmp_path / "no-camera.json"
    path.write_text(json.dumps(mapping))

    async def start():
        async def connector():
            return await rig.emulator.connect_in_memory()

        server = build_server(mount_url="in-process emulator", mapping_path=path, site=rig.site,
                              clock=rig.clock, connector=connector)
        return server, await server.start("ws://127.0.0.1:0")

    server, url = rig.run(start())
    try:
        with pytest.raises(VssRequestError) as err:
            call_server(url, "pointing_sample", {"star": "Vega"})
        assert err.value.code == "mapping"
        assert "guide_measure" in err.value.message and "guide camera" in err.value.message
        res = runner.invoke(app, ["pointing-run", "--stars", "3", "-o", str(tmp_path / "r.dat"),
                                  "--server", url])
        assert res.exit_code == 1 and "guide camera" in res.output
        assert not (tmp_path / "r.dat").exists()
    finally:
        rig.run(server.close())


@pytest.mark.parametrize(("args", "message"), [
    (["--stars", "0"], "--stars"),
    (["--at", "yesterday-ish"], "yesterday-ish"),
    (["-o", "/nonexistent-folder/run.dat"], "does not exist"),
    (["--min-el", "95"], "--min-el"),
])
def test_pointing_run_refuses_bad_arguments_with_the_reason(hidden, args, message):
    rig, _ = hidden
    res = runner.invoke(app, ["pointing-run", *args, "--server", rig.url])
    assert res.exit_code == 2, res.output
    assert message in res.output


def test_passive_mode_refuses_pointing_samples_and_a_star_below_the_limit_is_unreachable(hidden):
    rig, _ = hidden
    assert vs("mode", "passive", "--server", rig.url) == {"mode": "passive"}
    try:
        with pytest.raises(VssRequestError) as err:
            call_server(rig.url, "pointing_sample", {"star": "Vega"})
        assert err.value.code == "passive"
    finally:
        assert vs("mode", "active", "--server", rig.url) == {"mode": "active"}
    with pytest.raises(VssRequestError) as err:
        call_server(rig.url, "pointing_sample", {"az_deg": 10.0, "el_deg": 2.0})
    assert err.value.code == "unreachable" and "elevation 2.00" in err.value.message
    res = runner.invoke(app, ["mode", "sleepy", "--server", rig.url])
    assert res.exit_code == 2 and "sleepy" in res.output
