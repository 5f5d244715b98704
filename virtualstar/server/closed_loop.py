"""Closed-loop tracking: the guide camera's centroids steer the offsets of the track.

Beside a satellite pass (or a sky track: an autoguider) the loop polls the camera
every `POLL_S` of mount time for the frames read out since the last one
(camera_link.py) and, for each frame taken after the join:

1. **Where the target was.** The demand D(t) at the frame's mid-exposure time t is
   the fed path with the offsets the mount had then (their history is kept); the
   target is D(t) plus the centroid (dx = ΔA·cos E, dy = ΔE). Relative to the
   *nominal* path P (the prediction without offsets):
   * satellite: the along-track time τ and the across offset c that put it at
     P(t + τ) + c·ĉ (ĉ: the direction of travel turned 90° to the left), found by
     Newton steps τ ← τ + (T − P(t+τ))·û / ω from the current estimate;
   * star: the east (ξ) and north (η) offsets, through the parallactic angle.
2. **Filter.** The measurement goes to `estimator.PairFilter` (a documented
   constant-velocity Kalman filter per axis with an innovation gate): a frame
   that jumps implausibly (another object) is refused; a frame without the target
   (clouds, dropouts) leaves the estimate held, moving on at its rate.
3. **Steer.** After each accepted frame the estimate, moved on to the mount time
   where the change can start (now + 20 ms with `traj_replace`), is applied as the
   path/transverse (or ra/dec) offsets' new goal and rate (`Offsets.steer`), within
   the offset limits (corrections.py).

The loop's state is in the operation's info (`closed_loop`) and `status`; it logs
when it locks, refuses a jump, starts again and loses the camera. It never ends
the track: without frames the track goes on with the last estimate.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
from collections.abc import AsyncIterator
from typing import TYPE_CHECKING, Any

import erfa
import numpy as np

from virtualstar.astro import iso_utc
from virtualstar.astro.constants import ARCSEC_PER_RAD

from .camera_link import CameraFrame, CameraLink
from .corrections import Corrections
from .estimator import FilterConfig, PairFilter
from .exceptions import VssError
from .operations import Operation

if TYPE_CHECKING:
    from .station import Station

__all__ = ["POLL_S", "ClosedLoop", "running"]

log = logging.getLogger("virtualstar.server")

POLL_S = 0.05  # mount seconds between two polls of the camera
NEWTON_STEPS = 3
RATE_STEP_US = 100_000  # the direction of travel from the path 0.1 s on
MAX_PATH_S = 30.0  # as steering.MAX_PATH_S: the pass's planned margin
UNREACHABLE_RETRY_S = 1.0


class ClosedLoop:
    """One loop: a track's corrections, the camera, the filter and what it did."""

    def __init__(self, t: Station, op: Operation, corrections: Corrections, kind: str,
                 camera: CameraLink, config: FilterConfig) -> None:
        if kind not in ("satellite", "sky"):
            raise ValueError(f"closed loop kind {kind!r}: expected 'satellite' or 'sky'")
        self.t = t
        self.op = op
        self.corrections = corrections
        self.kind = kind
        self.camera = camera
        self.filter = PairFilter(config)
        self.axes = ("guide_path", "guide_transverse") if kind == "satellite" else \
            ("guide_ra", "guide_dec")
        self.seq = -1
        self.info: dict[str, Any] = {"kind": kind, "state": "searching", "frames": 0,
                                     "found": 0, "accepted": 0, "refused": 0, "held": 0,
                                     "corrections": 0, "camera_error": None}
        op.info["closed_loop"] = self.info

    # ------------------------------------------------------------------ the loop
    async def run(self) -> None:
        """Poll, filter, steer until cancelled (the track's end)."""
        first = True
        while True:
            try:
                frames = await self.camera.frames_since(self.seq)
            except VssError as exc:
                self._camera_lost(str(exc))
                await self.t.clock.sleep(UNREACHABLE_RETRY_S)
                continue
            self.info["camera_error"] = None
            if first:  # frames from before the loop began are not this track's
                first = False
                if frames:
                    self.seq = frames[-1].seq
                    frames = []
            steer = False
            for frame in frames:
                self.seq = max(self.seq, frame.seq)
                steer |= self.take(frame)
            if steer:
                await self.steer()
            await self.t.clock.sleep(POLL_S)

    def take(self, f: CameraFrame) -> bool:
        """Take one frame; return True if it was accepted (the offsets should follow)."""
        join = self.corrections.not_before_us
        path = self.corrections.path
        if path is None or join is None or f.t_us < join:
            return False  # still on the run-up: the frame says nothing about the path
        self.info["frames"] += 1
        self.info["last_frame_utc"] = iso_utc(f.t_us, 3)
        if not f.found:
            self.info["held"] += 1
            if self.filter.locked:
                self.filter.hold(f.t_us, self._scale(f.t_us))
                self.info["state"] = f"holding ({f.why or 'no target'})"
            return False
        self.info["found"] += 1
        try:
            z, scale = self.measure(f)
        except (VssError, ValueError, FloatingPointError) as exc:
            log.warning("closed loop of operation %s: frame %d not used: %s", self.op.id,
                        f.seq, exc)
            return False
        was_locked = self.filter.locked
        ok = self.filter.frame(f.t_us, z, scale)
        self.info["accepted"], self.info["refused"] = self.filter.accepted, self.filter.refused
        self.info["last_d2"] = None if math.isnan(self.filter.last_d2) else self.filter.last_d2
        if ok and not was_locked:
            self._event("info", f"locked on the target (frame {f.seq})")
        if not ok:
            if self.info["state"] != "refusing":
                self._event("warning", f"refused frame {f.seq}: it jumped (d² = "
                                       f"{self.filter.last_d2:.0f} > {self.filter.config.gate:g}); "
                                       "another object or a glitch")
            self.info["state"] = "refusing"
            if not self.filter.locked:
                self._event("warning", "refusing frames for longer than "
                                       f"{self.filter.config.relock_after_s:g} s: starting again")
            return False
        self.info["state"] = "locked"
        self._note_estimate(f.t_us)
        return True

    async def steer(self) -> None:
        """Apply the estimate, moved on to where the change starts, to the offsets."""
        est = self.filter
        a1, a2 = self.axes

        def change(offsets, from_us: int, sky_rate: float | None) -> int:
            (g1, r1), (g2, r2) = est.at(from_us)
            if self.kind == "satellite":
                g1 = max(-MAX_PATH_S, min(MAX_PATH_S, g1))
            reached = offsets.steer(a1, from_us, g1, r1, sky_rate_arcsec_s=sky_rate)
            return max(reached, offsets.steer(a2, from_us, g2, r2, sky_rate_arcsec_s=sky_rate))

        try:
            await self.corrections.apply("closed loop", change)
        except VssError as exc:
            log.warning("closed loop of operation %s: the correction was not sent: %s",
                        self.op.id, exc)
            return
        self.info["corrections"] += 1

    # ------------------------------------------------------------------ measuring
    def measure(self, f: CameraFrame) -> tuple[tuple[float, float], tuple[float, float]]:
        """The frame's target relative to the nominal path: ((z1, z2), (scale1, scale2))."""
        path = self.corrections.path
        assert path is not None
        d = path.sample(np.array([f.t_us], np.int64))
        d_az, d_el = float(d.az_rad[0]), float(d.el_rad[0])
        t_az = d_az + f.dx_arcsec / ARCSEC_PER_RAD / max(math.cos(d_el), 1e-3)
        t_el = d_el + f.dy_arcsec / ARCSEC_PER_RAD
        if self.kind == "sky":
            p = path.base.sample(np.array([f.t_us], np.int64))
            x, y = _tangent(t_az, t_el, float(p.az_rad[0]), float(p.el_rad[0]))
            lat = math.radians(self.t.config.site.lat_deg)
            ha, dec = erfa.ae2hd(float(p.az_rad[0]) % (2 * math.pi), float(p.el_rad[0]), lat)
            q = float(erfa.hd2pa(ha, dec, lat))
            east = -x * math.cos(q) + y * math.sin(q)
            north = x * math.sin(q) + y * math.cos(q)
            return (east, north), (1.0, 1.0)
        tau = self._tau_guess(f.t_us)
        for _ in range(NEWTON_STEPS):
            x, y, ux, uy, rate = self._relative(path.base, f.t_us, tau, t_az, t_el)
            tau += (x * ux + y * uy) / rate
            tau = max(-MAX_PATH_S, min(MAX_PATH_S, tau))
        x, y, ux, uy, rate = self._relative(path.base, f.t_us, tau, t_az, t_el)
        return (tau, -x * uy + y * ux), (1.0 / rate, 1.0)

    def _tau_guess(self, t_us: int) -> float:
        if self.filter.locked:
            return self.filter.axes[0].at(t_us)[0]
        return self.corrections.offsets.total("path", t_us)

    @staticmethod
    def _relative(base, t_us: int, tau: float, t_az: float, t_el: float):
        """(x, y) arcsec of the target from P(t + τ), the unit direction of travel, the rate."""
        at = t_us + int(round(tau * 1e6))
        p = base.sample(np.array([at, at + RATE_STEP_US], np.int64))
        x, y = _tangent(t_az, t_el, float(p.az_rad[0]), float(p.el_rad[0]))
        vx, vy = _tangent(float(p.az_rad[1]), float(p.el_rad[1]), float(p.az_rad[0]),
                          float(p.el_rad[0]))
        rate = math.hypot(vx, vy) / (RATE_STEP_US * 1e-6)
        if not rate > 1e-3:
            raise ValueError("the target does not move: no direction of travel")
        norm = math.hypot(vx, vy)
        return x, y, vx / norm, vy / norm, rate

    def _scale(self, t_us: int) -> tuple[float, float]:
        if self.kind == "sky":
            return 1.0, 1.0
        try:
            rate = self.corrections.sky_rate_at(t_us)
        except VssError:
            rate = None
        return (1.0 / rate if rate else 1.0), 1.0

    # ------------------------------------------------------------------ reporting
    def _note_estimate(self, t_us: int) -> None:
        (v1, r1), (v2, r2) = self.filter.at(t_us)
        s1, s2 = self.filter.sigma()
        if self.kind == "satellite":
            self.info.update({"along_s": v1, "along_rate_s_per_s": r1, "across_arcsec": v2,
                              "across_rate_arcsec_s": r2, "along_sigma_s": s1,
                              "across_sigma_arcsec": s2})
        else:
            self.info.update({"east_arcsec": v1, "east_rate_arcsec_s": r1, "north_arcsec": v2,
                              "north_rate_arcsec_s": r2, "east_sigma_arcsec": s1,
                              "north_sigma_arcsec": s2})

    def _camera_lost(self, why: str) -> None:
        if self.info["camera_error"] is None:
            self._event("warning", f"the guide camera cannot be read: {why}; the track goes on "
                                   "with the last estimate")
        self.info["camera_error"] = why
        self.info["state"] = "camera unreachable"

    def _event(self, level: str, text: str) -> None:
        self.t.log_event(level, "closed_loop", f"operation {self.op.id}: closed loop: {text}",
                         id=self.op.id)
        self.t.emit("closed_loop", {"id": self.op.id, "text": text})


def _tangent(az: float, el: float, az0: float, el0: float) -> tuple[float, float]:
    """(x, y) arcsec of (az, el) from (az0, el0): azimuth·cos E to the right, elevation up."""
    d_az = math.remainder(az - az0, 2 * math.pi)
    return d_az * math.cos(el0) * ARCSEC_PER_RAD, (el - el0) * ARCSEC_PER_RAD


@contextlib.asynccontextmanager
async def running(t: Station, op: Operation, corrections: Corrections, kind: str,
                  enabled: bool) -> AsyncIterator[ClosedLoop | None]:
    """Run the closed loop (if `enabled`) while the block runs; it ends with the block."""
    if not enabled:
        yield None
        return
    camera = t.steering.camera
    if camera is None:  # checked when the command came; a camera dropped since: open loop
        op.info["closed_loop"] = {"state": "no camera: open loop"}
        yield None
        return
    loop = ClosedLoop(t, op, corrections, kind, camera, t.steering.filter_config)

    async def guarded() -> None:
        try:
            await loop.run()
        except Exception as exc:  # a bug must not end the track: it goes on open loop
            log.exception("closed loop of operation %s failed", op.id)
            loop.info["state"] = f"failed: {type(exc).__name__}: {exc}; open loop"

    task = asyncio.get_running_loop().create_task(guarded(), name="vss-closed-loop")
    try:
        yield loop
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task
