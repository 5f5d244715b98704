"""The pointing model in the loop: a mount with hidden geometry puts the star on axis
only when the VSS applies the matching model.

The emulator's guide camera knows the true (hidden) geometry and reports how
far a star at a given observed position is from the optical axis. With the
model loaded the star must sit on the axis; without it, off by the geometry.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner
from vss_rig import Rig

from astcom_client import Client
from pointing_model import model_from_values
from virtualstar.astro import UtcTimes, load_site, observe_mount_times, resolve_target
from virtualstar.cli.main import app

runner = CliRunner()
TERMS = {"IA": 120.0, "IE": -45.0, "CA": 30.0, "AN": 15.0}


@pytest.fixture(scope="module")
def tilted(tmp_path_factory):
    start_us = int(UtcTimes.from_iso(["2024-05-18T19:40:00Z"]).to_unix_us()[0])
    rig = Rig(start_us=start_us, site=load_site(),
              emulator_options={"geometry_arcsec": {k.lower(): v for k, v in TERMS.items()},
                                "seeing_arcsec": 0.0}).start()
    path = tmp_path_factory.mktemp("model") / "model.json"
    model_from_values(TERMS).save(path)
    yield rig, path
    rig.close()


def guide_offset_arcsec(rig) -> float:
    """Return Vega's distance from the optical axis seen by the emulator's guide camera.

    The camera looks at the encoders of the instant it is asked, some time after the star's
    place was computed (longer on a loaded host, and mount time runs ×speed): the star drifts
    meanwhile. So the star is computed at t0 (before asking) and t1 (after the answer); the
    camera's instant lies between, and the pointing error is the measured offset minus the
    part f ∈ [0, 1] of the drift that fits it best. Host speed widens the bracket, never the
    error found.
    """
    def star_at(t_us: int) -> tuple[float, float]:
        obs = observe_mount_times(resolve_target("Vega"), np.array([t_us]), rig.site)
        return float(obs.az_rad[0]), float(obs.el_rad[0])

    async def measure():
        async with await Client.connect(rig.emulator.url) as c:
            _, _, t0 = await c.read_at(["time.mount_us"])
            az0, el0 = star_at(t0)
            dx, dy = await c.invoke("guide.measure", float(np.degrees(az0)),
                                    float(np.degrees(el0)))
            _, _, t1 = await c.read_at(["time.mount_us"])
        return (az0, el0), star_at(t1), np.array([dx, dy])

    (az0, el0), (az1, el1), measured = rig.run(measure())
    arcsec = np.degrees(1.0) * 3600
    drift = np.array([(az0 - az1) * np.cos(el0), el0 - el1]) * arcsec  # star(t0) − star(t1)
    f = float(np.clip(measured @ drift / (drift @ drift), 0.0, 1.0)) if drift.any() else 0.0
    return float(np.hypot(*(f * drift - measured)))


def test_with_the_matching_model_loaded_the_star_lands_on_the_optical_axis(tilted):
    rig, path = tilted
    res = runner.invoke(app, ["slew", "--star", "Vega", "--server", rig.url, "--json"])
    assert res.exit_code == 0, res.output
    without = guide_offset_arcsec(rig)
    assert without > 50.0  # the hidden geometry is there
    rig.run(rig.server.telescope.link.wait_connected(5))
    from virtualstar.vss_client import call_server

    loaded = call_server(rig.url, "load_model", {"path": str(path)})
    assert loaded["terms"]["IA"] == 120.0
    res = runner.invoke(app, ["slew", "--star", "Vega", "--server", rig.url, "--json"])
    assert res.exit_code == 0, res.output
    with_model = guide_offset_arcsec(rig)
    assert with_model < 2.0, (without, with_model)
    st = json.loads(runner.invoke(app, ["status", "--server", rig.url, "--json"]).stdout)
    assert st["pointing_model"] == str(path)
    # the observed position reported is the star's, not the encoders'
    obs = observe_mount_times(resolve_target("Vega"), np.array([st["mount_time_us"]]), rig.site)
    d_el = (st["observed"]["el_deg"] - np.degrees(obs.el_rad[0])) * 3600
    assert abs(d_el) < 2.0
    call_server(rig.url, "unload_model")
    runner.invoke(app, ["stop", "--server", rig.url])
