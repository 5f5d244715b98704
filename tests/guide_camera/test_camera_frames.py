"""Frames from known inputs: the centroid, its noise, exposure smear, field, clouds, dropouts."""

from __future__ import annotations

import math

import numpy as np
import pytest

from guide_camera import CameraConfig, CameraConfigError, FrameMaker, Weather

ARCSEC = math.pi / 180 / 3600
T0 = 1_716_000_000_000_000


class LineTruth:
    """A target moving along azimuth at a known rate from a known place (synthetic truth)."""

    def __init__(self, az0: float, el0: float, rate_arcsec_s: float) -> None:
        self.az0, self.el0, self.rate = az0, el0, rate_arcsec_s

    def place(self, t_us):
        s = (np.asarray(t_us) - T0) * 1e-6
        return self.az0 + self.rate * s * ARCSEC / math.cos(self.el0), np.full(len(s), self.el0)


def _exposure(cfg: CameraConfig, t0: int):
    t = t0 + cfg.sample_offsets_us()
    return t, t  # mount and true time equal here


def test_the_centroid_is_the_mean_offset_over_the_exposure_with_the_noise_asked():
    cfg = CameraConfig(noise_arcsec=0.5, exposure_s=0.05, seed=4)
    truth = LineTruth(1.0, 0.7, rate_arcsec_s=100.0)
    maker = FrameMaker(cfg, truth, np.zeros(7))
    dx, dy = [], []
    for k in range(2000):
        t, tt = _exposure(cfg, T0 + k * 100_000)
        # the axis sits still on where the target is at the middle of the exposure
        mid = int(np.mean(t))
        az, el = truth.place(np.array([mid]))
        f = maker.frame(k, t, tt, np.full(len(t), az[0] - 20 * ARCSEC / math.cos(0.7)),
                        np.full(len(t), el[0] + 5 * ARCSEC), Weather())
        assert f.found and f.t_us == mid
        assert f.ready_us == T0 + k * 100_000 + 100_000  # exposure 50 ms + read-out 50 ms
        dx.append(f.dx_arcsec)
        dy.append(f.dy_arcsec)
        assert f.true_dx_arcsec == pytest.approx(20.0, abs=1e-6)
    assert np.mean(dx) == pytest.approx(20.0, abs=0.05)
    assert np.mean(dy) == pytest.approx(-5.0, abs=0.05)
    assert np.std(dx) == pytest.approx(0.5, rel=0.06)
    assert np.std(dy) == pytest.approx(0.5, rel=0.06)


def test_clouds_dropouts_the_field_and_an_impostor_decide_what_a_frame_shows():
    cfg = CameraConfig(noise_arcsec=0.0, dropout_fraction=0.2, fov_radius_arcsec=100.0, seed=1)
    truth = LineTruth(1.0, 0.7, rate_arcsec_s=0.0)
    maker = FrameMaker(cfg, truth, np.zeros(7))
    weather = Weather(clouds=[(T0 + 1_000_000, T0 + 2_000_000)],
                      impostors=[(T0 + 3_000_000, T0 + 4_000_000, 60.0, 0.0)])
    why = []
    for k in range(50):
        t, tt = _exposure(cfg, T0 + k * 100_000)
        f = maker.frame(k, t, tt, np.full(len(t), 1.0 - 50 * ARCSEC / math.cos(0.7)),
                        np.full(len(t), 0.7), weather)
        why.append(f.why)
        if 10 <= k < 20:
            assert f.why == "clouds" and not f.found and math.isnan(f.dx_arcsec)
        if 30 <= k < 40:  # the impostor 60″ beyond the target: outside a 100″ field
            assert f.why in ("outside_field", "dropout")
        if f.found:
            assert f.dx_arcsec == pytest.approx(50.0, abs=1e-6)
    assert 3 <= why.count("dropout") <= 12  # 20 % of the 30 frames neither clouded nor impostor


def test_camera_settings_out_of_range_are_refused_naming_the_setting():
    for kwargs, name in (({"noise_arcsec": -1.0}, "noise_arcsec"),
                         ({"dropout_fraction": 1.5}, "dropout_fraction"),
                         ({"exposure_s": 0.5, "period_s": 0.1}, "exposure_s"),
                         ({"samples_per_exposure": 0}, "samples_per_exposure")):
        with pytest.raises(CameraConfigError, match=name):
            CameraConfig(**kwargs)
