"""What one camera frame shows: pure functions of the truth and the encoder samples.

No I/O and no clock. A frame is exposed from `t_start` for `exposure_s`; the
device samples the mount's encoders (and true UTC) at `samples_per_exposure`
instants inside the exposure. The target's centroid relative to the optical axis
is the mean over those instants of

    dx = (A_target − A_axis)·cos E_target,  dy = E_target − E_axis   (arcsec)

— the image smears as a real one does — plus Gaussian centroid noise. The axis is
the encoders through the hidden geometry (boresight.py), the target its true
observed place at the true UTC of each sample (truth.py). Frames are read out
`readout_latency_s` after the exposure ends. A frame shows nothing when the
target is outside the field, when a cloud covers the sky (scheduled windows), or
at random (`dropout_fraction`); inside an impostor window the brightest object
in the field is another one, at a fixed offset from the target.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .boresight import axis_place
from .exceptions import CameraConfigError

__all__ = ["CameraConfig", "Frame", "FrameMaker", "Weather"]

ARCSEC_PER_RAD = 180.0 / math.pi * 3600.0


@dataclass(frozen=True)
class CameraConfig:
    """The camera's timing, noise and field (seconds, arcseconds)."""

    period_s: float = 0.1  # one frame every 0.1 s (10 Hz)
    exposure_s: float = 0.05
    samples_per_exposure: int = 5  # encoder readings averaged into one centroid
    readout_latency_s: float = 0.05  # from the end of the exposure to the frame's availability
    noise_arcsec: float = 0.5  # 1-σ centroid noise per axis
    fov_radius_arcsec: float = 3600.0  # a 2°-wide acquisition camera
    dropout_fraction: float = 0.0  # frames lost at random (0..1)
    seed: int = 0

    def __post_init__(self) -> None:
        checks = (("period_s", 0.01, 60.0), ("exposure_s", 1e-4, 60.0),
                  ("readout_latency_s", 0.0, 10.0), ("noise_arcsec", 0.0, 100.0),
                  ("fov_radius_arcsec", 1.0, 36_000.0), ("dropout_fraction", 0.0, 1.0))
        for name, lo, hi in checks:
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not lo <= v <= hi:
                raise CameraConfigError(f"camera {name}={v!r}: expected {lo:g}..{hi:g}")
        if self.exposure_s > self.period_s:
            raise CameraConfigError(f"camera exposure_s={self.exposure_s:g} is longer than the "
                                    f"frame period {self.period_s:g} s")
        if not (isinstance(self.samples_per_exposure, int) and 1 <= self.samples_per_exposure <= 50):
            raise CameraConfigError("camera samples_per_exposure: expected an integer 1..50")

    def sample_offsets_us(self) -> np.ndarray:
        """Instants inside an exposure (from its start) where the encoders are read."""
        n = self.samples_per_exposure
        return np.round((np.arange(n) + 0.5) / n * self.exposure_s * 1e6).astype(np.int64)


@dataclass(frozen=True)
class Frame:
    """One frame: mount times (µs), what it shows (arcsec), and the hidden truth of it."""

    seq: int
    t_us: int  # middle of the exposure, mount time
    ready_us: int  # when it is read out and available, mount time
    found: bool
    dx_arcsec: float  # target minus optical axis: azimuth·cos E (right), elevation (up)
    dy_arcsec: float
    why: str = ""  # why nothing was found: outside_field, clouds, dropout
    true_dx_arcsec: float = math.nan  # the noiseless offset of the true target (truth only)
    true_dy_arcsec: float = math.nan

    def as_dict(self) -> dict:
        return {"seq": self.seq, "t_us": self.t_us, "ready_us": self.ready_us,
                "found": self.found, "dx_arcsec": self.dx_arcsec, "dy_arcsec": self.dy_arcsec,
                "why": self.why}


@dataclass
class Weather:
    """Scheduled clouds and impostors, in mount time (µs)."""

    clouds: list[tuple[int, int]] = field(default_factory=list)
    impostors: list[tuple[int, int, float, float]] = field(default_factory=list)

    def cloudy(self, t_us: int) -> bool:
        return any(a <= t_us < b for a, b in self.clouds)

    def impostor(self, t_us: int) -> tuple[float, float] | None:
        for a, b, dx, dy in self.impostors:
            if a <= t_us < b:
                return dx, dy
        return None


class FrameMaker:
    """Turn encoder samples of one exposure into a frame (random numbers from `seed`)."""

    def __init__(self, config: CameraConfig, truth, geometry_arcsec) -> None:
        self.config = config
        self.truth = truth  # .place(true_us) -> (az, el) radians
        self.geometry = np.asarray(geometry_arcsec, float)
        self.rng = np.random.default_rng(config.seed)

    def frame(self, seq: int, mount_us: np.ndarray, true_us: np.ndarray, enc_az: np.ndarray,
              enc_el: np.ndarray, weather: Weather) -> Frame:
        """A frame from the readings inside its exposure (mount and true µs, encoders rad)."""
        cfg = self.config
        mount_us = np.asarray(mount_us, np.int64)
        t_mid = int(round(float(mount_us.mean())))
        ready = int(mount_us[0] - cfg.sample_offsets_us()[0]) + int(
            round((cfg.exposure_s + cfg.readout_latency_s) * 1e6))
        axis_az, axis_el = axis_place(self.geometry, enc_az, enc_el)
        tgt_az, tgt_el = self.truth.place(np.asarray(true_us, np.int64))
        d_az = np.remainder(tgt_az - axis_az + math.pi, 2 * math.pi) - math.pi
        dx = float(np.mean(d_az * np.cos(tgt_el))) * ARCSEC_PER_RAD
        dy = float(np.mean(tgt_el - axis_el)) * ARCSEC_PER_RAD
        # the random draws happen for every frame, so a run's noise does not depend on
        # which frames were lost
        noise = self.rng.normal(0.0, cfg.noise_arcsec, 2)
        lost = self.rng.random() < cfg.dropout_fraction
        seen_dx, seen_dy = dx, dy
        impostor = weather.impostor(t_mid)
        if impostor is not None:
            seen_dx, seen_dy = dx + impostor[0], dy + impostor[1]
        why = ""
        if weather.cloudy(t_mid):
            why = "clouds"
        elif lost:
            why = "dropout"
        elif math.hypot(seen_dx, seen_dy) > cfg.fov_radius_arcsec:
            why = "outside_field"
        if why:
            return Frame(seq, t_mid, ready, False, math.nan, math.nan, why, dx, dy)
        return Frame(seq, t_mid, ready, True, seen_dx + float(noise[0]),
                     seen_dy + float(noise[1]), "", dx, dy)
