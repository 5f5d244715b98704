"""The closed loop's filter: two constant-velocity Kalman filters and an innovation gate.

Pure numerics: no I/O, no clock. Written to be followed line by line (docs/vss.md,
"Closed loop").

Each axis has the state s = [x, ẋ] (the offset and its rate; along-track: seconds,
s/s; across, east, north: arcsec, arcsec/s) and its 2×2 covariance P. Between two
frames Δt apart the state moves on at its rate and grows uncertain as if a white
random acceleration of spectral density q acted (the textbook constant-velocity
model):

    F = [[1, Δt], [0, 1]]            s ← F·s
    Q = q·[[Δt³/3, Δt²/2], [Δt²/2, Δt]]      P ← F·P·Fᵀ + Q

A frame measures x alone (H = [1, 0]) with variance R: the innovation ν = z − x,
its variance S = P₀₀ + R, the gain K = P·Hᵀ/S, then s ← s + K·ν, P ← (I − K·H)·P.

Both axes of a frame are gated together: d² = ν₁²/S₁ + ν₂²/S₂ is chi-square with
two degrees of freedom when the frame shows the target; a frame with d² above
`gate` (25: a 1-in-270 000 event for the target) is another object or a glitch and
is refused — counted, the state left as predicted. A refusal run longer than
`relock_after_s` means the filter, not the frame, is wrong: it starts again from the
next frame (documented limitation: an impostor that stays longer is followed).
No frame (clouds, dropouts) means no update: the estimate is held, moving on at its
rate, and the gate widens as P grows.

Along the track the filter runs in seconds, but its noise is set in sky units:
R = (σ/ω)² and q = q_sky/ω² with ω the target's sky rate (arcsec/s) at the frame,
so the loop behaves the same on the sky at 5° and at 80° of elevation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

__all__ = ["AxisFilter", "FilterConfig", "PairFilter"]


@dataclass(frozen=True)
class FilterConfig:
    """The filter's noises and gate (sky units: arcsec, arcsec²/s³)."""

    noise_arcsec: float = 0.5  # 1-σ centroid noise per axis (the camera's)
    q_arcsec2_s3: float = 0.05  # random-acceleration spectral density on the sky (tuned: docs)
    gate: float = 25.0  # chi-square (2 dof) above which a frame is refused
    relock_after_s: float = 10.0  # refusals for this long: start again
    initial_rate_sigma_arcsec_s: float = 30.0  # how fast the offset may drift at the start


@dataclass
class AxisFilter:
    """One axis: state [x, ẋ] and covariance P (x in the axis's unit)."""

    x: np.ndarray = field(default_factory=lambda: np.zeros(2))
    p: np.ndarray = field(default_factory=lambda: np.eye(2))
    t_us: int | None = None

    def start(self, z: float, r: float, rate_var: float, t_us: int) -> None:
        self.x = np.array([z, 0.0])
        self.p = np.diag([r, rate_var])
        self.t_us = t_us

    def predict(self, t_us: int, q: float) -> None:
        if self.t_us is None:
            return
        dt = (t_us - self.t_us) * 1e-6
        if dt <= 0:
            return
        f = np.array([[1.0, dt], [0.0, 1.0]])
        qm = q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
        self.x = f @ self.x
        self.p = f @ self.p @ f.T + qm
        self.t_us = t_us

    def innovation(self, z: float, r: float) -> tuple[float, float]:
        return z - float(self.x[0]), float(self.p[0, 0]) + r

    def update(self, z: float, r: float) -> None:
        nu, s = self.innovation(z, r)
        k = self.p[:, 0] / s
        self.x = self.x + k * nu
        self.p = self.p - np.outer(k, self.p[0, :])

    def at(self, t_us: int) -> tuple[float, float]:
        """The estimate moved on to `t_us`: (offset, rate)."""
        dt = 0.0 if self.t_us is None else (t_us - self.t_us) * 1e-6
        return float(self.x[0] + self.x[1] * dt), float(self.x[1])


@dataclass
class PairFilter:
    """The two axes of one loop (along + across, or east + north) and the gate."""

    config: FilterConfig = field(default_factory=FilterConfig)
    axes: tuple[AxisFilter, AxisFilter] = field(
        default_factory=lambda: (AxisFilter(), AxisFilter()))
    locked: bool = False
    accepted: int = 0
    refused: int = 0
    refusing_since_us: int | None = None
    last_d2: float = math.nan

    def frame(self, t_us: int, z: tuple[float, float],
              scale: tuple[float, float] = (1.0, 1.0)) -> bool:
        """Take one frame's measurement `z` at `t_us`; return whether it was accepted.

        `scale` turns sky arcseconds into each axis's unit (along: 1/ω s per arcsec).
        """
        cfg = self.config
        r = [(cfg.noise_arcsec * s) ** 2 for s in scale]
        q = [cfg.q_arcsec2_s3 * s * s for s in scale]
        if not self.locked:
            for ax, zi, ri, si in zip(self.axes, z, r, scale, strict=True):
                ax.start(zi, ri, (cfg.initial_rate_sigma_arcsec_s * si) ** 2, t_us)
            self.locked, self.refusing_since_us = True, None
            self.accepted += 1
            return True
        for ax, qi in zip(self.axes, q, strict=True):
            ax.predict(t_us, qi)
        d2 = 0.0
        for ax, zi, ri in zip(self.axes, z, r, strict=True):
            nu, s = ax.innovation(zi, ri)
            d2 += nu * nu / s
        self.last_d2 = d2
        if d2 > cfg.gate:
            self.refused += 1
            if self.refusing_since_us is None:
                self.refusing_since_us = t_us
            elif (t_us - self.refusing_since_us) * 1e-6 > cfg.relock_after_s:
                self.locked = False  # the next frame starts the filter again
            return False
        for ax, zi, ri in zip(self.axes, z, r, strict=True):
            ax.update(zi, ri)
        self.refusing_since_us = None
        self.accepted += 1
        return True

    def hold(self, t_us: int, scale: tuple[float, float] = (1.0, 1.0)) -> None:
        """A frame without the target: predict only (the estimate holds, P grows)."""
        if not self.locked:
            return
        for ax, s in zip(self.axes, scale, strict=True):
            ax.predict(t_us, self.config.q_arcsec2_s3 * s * s)

    def at(self, t_us: int) -> tuple[tuple[float, float], tuple[float, float]]:
        """((offset 1, rate 1), (offset 2, rate 2)) moved on to `t_us`."""
        return self.axes[0].at(t_us), self.axes[1].at(t_us)

    def sigma(self) -> tuple[float, float]:
        return tuple(float(math.sqrt(max(ax.p[0, 0], 0.0))) for ax in self.axes)  # type: ignore[return-value]
