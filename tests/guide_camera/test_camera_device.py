"""The camera as an ASTCom device beside the emulator, in lockstep: what it sees and when.

Truth here is independent of the camera's code: astropy's place of Vega and the
emulator's own geometry code (`mount_emulator.Geometry`) applied to the encoders the
test streams itself from the emulator.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from signal_recording import recording
from sky_truth import star_truth
from vss_rig import run_lockstep_scenario

from catalogs import bright_stars
from guide_camera import CameraConfig
from virtualstar.astro import load_site
from virtualstar.launcher import star_camera

START = "2024-05-18T22:00:00Z"
GEOMETRY_SEED = 11  # hidden pointing errors of about 100″ that no model corrects


def _vega_camera(site, **config):
    v = bright_stars().lookup("Vega")
    return star_camera(v.ra_deg, v.dec_deg, site, config=CameraConfig(**config),
                       pm_ra_cosdec_mas_yr=v.pm_ra_cosdec_mas_yr, pm_dec_mas_yr=v.pm_dec_mas_yr,
                       parallax_mas=v.parallax_mas, rv_km_s=v.rv_km_s or 0.0,
                       epoch_jyear=v.epoch_jyear)


def test_frames_show_vega_where_the_hidden_geometry_puts_it_and_come_out_at_their_read_out():
    from mount_emulator import Geometry
    from virtualstar.launcher import hidden_geometry_arcsec

    site = load_site()
    geometry = hidden_geometry_arcsec(seed=GEOMETRY_SEED)

    async def scenario(vss, clock):
        c = vss.client()
        await c.request("track", {"star": "Vega"})
        cam = await vss.camera.connect_in_memory(name="test")
        try:
            seen, early = -1, []
            async with recording(vss, ["axis.az.position", "axis.el.position"],
                                 clock=clock) as rec:
                for _ in range(60):
                    await clock.sleep(0.05)
                    now = clock.now_us
                    frames = json.loads(await cam.invoke("frames.since", seen))
                    early += [f for f in frames if f["ready_us"] > now]
                    if frames:
                        seen = frames[-1]["seq"]
            frames = [f for f in vss.camera.device.frames if f.found]
        finally:
            await cam.close()
        return frames, early, rec

    frames, early, rec = run_lockstep_scenario(
        START, scenario, geometry_arcsec=geometry, camera=_vega_camera(site, noise_arcsec=0.0))
    assert not early  # no frame is seen before it is read out
    geom = Geometry.from_mapping(geometry)
    t = rec.t_us
    inside = [f for f in frames if t[0] + 50_000 < f.t_us < t[-1] - 50_000]
    assert len(inside) >= 25
    for f in inside:
        # the exposure's mean: the star moves 15″/s, so the middle instant stands for it
        k = np.searchsorted(t, f.t_us)
        axis_az, axis_el = geom.sky_of_encoder(rec["axis.az.position"][k],
                                               rec["axis.el.position"][k])
        az, el = (math.radians(x[0]) for x in star_truth("Vega", np.array([f.t_us]), site))
        dx = math.remainder(az - float(axis_az), 2 * math.pi) * math.cos(el) * 206264.806
        dy = (el - float(axis_el)) * 206264.806
        assert f.dx_arcsec == pytest.approx(dx, abs=0.05)
        assert f.dy_arcsec == pytest.approx(dy, abs=0.05)
        assert math.hypot(dx, dy) > 30.0  # the hidden geometry shows: open loop is off


def test_the_camera_refuses_hostile_calls_and_settings_and_keeps_running():
    from astcom_client import DeviceError

    site = load_site()

    async def scenario(vss, clock):
        cam = await vss.camera.connect_in_memory(name="test")
        errors = []
        try:
            for name, args in (("frames.since", (-(2**62),)), ("camera.add_clouds", (5, 1)),
                               ("camera.add_impostor", (1, 5, float("nan"), 0.0)),
                               ("camera.set_satellite", ("1 bad", "2 bad"))):
                try:
                    out = await cam.invoke(name, *args)
                    errors.append((name, "ok", out))
                except DeviceError as exc:
                    errors.append((name, "refused", str(exc)))
            for value in (-1.0, 2.0, float("nan")):
                try:
                    await cam.write({"camera.dropout_fraction": value})
                    errors.append(("write", "ok", value))
                except Exception as exc:  # a refused write: 422
                    errors.append(("write", "refused", str(exc)))
            await clock.sleep(1.0)
            frames = json.loads(await cam.invoke("frames.since", -1))
        finally:
            await cam.close()
        return errors, frames

    errors, frames = run_lockstep_scenario(START, scenario, camera=_vega_camera(site))
    outcome = {name: how for name, how, _ in errors[:4]}
    assert outcome == {"frames.since": "ok", "camera.add_clouds": "refused",
                       "camera.add_impostor": "refused", "camera.set_satellite": "refused"}
    assert [how for name, how, _ in errors[4:]] == ["refused"] * 3
    assert len(frames) >= 8  # still taking frames
