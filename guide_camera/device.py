"""The guide camera simulator as an ASTCom device beside the mount emulator.

It reads the mount over ASTCom like any other client (its encoders, its mount and
true clocks, and once the hidden geometry `truth.geometry_arcsec`), computes a
frame every `period_s` (frames.py) and publishes it: every frame is one "tick" of
its Endpoint (loop rate = frame rate), stamped with the middle of its exposure in
mount time, so a stream of `frame.*` gives each frame once (the panel, the
recorder), and `frames.since(seq)` returns the frames read out since a sequence
number (the VSS's closed loop polls it).

Time comes from a clock object with ``async sleep_until_us(t_us)`` in mount time:
the `virtualstar.lockstep.LockstepClock` the emulator runs on (the camera then
reads the encoders exactly at each sampling instant and publishes each frame
exactly at its read-out time, deterministically), or `MountPacedClock`, which
follows a mount running by itself from its `time.mount_us`.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import json
import logging
import math
from collections import deque
from collections.abc import Awaitable, Callable
from typing import Any

import numpy as np

from astcom_client import Client, Collection, Endpoint, EndpointConfig

from .exceptions import CameraConfigError
from .frames import CameraConfig, Frame, FrameMaker, Weather
from .truth import CameraSite, SatelliteTruth, StarTruth

__all__ = ["EMULATOR_NAMES", "GuideCameraDevice", "MountPacedClock"]

log = logging.getLogger("guide_camera")

#: What the camera reads from the mount (the mount emulator's names).
EMULATOR_NAMES = {"az": "axis.az.position", "el": "axis.el.position",
                  "mount_us": "time.mount_us", "true_us": "time.true_us",
                  "geometry": "truth.geometry_arcsec"}
KEEP_FRAMES = 20_000  # frames kept for frames.since (about half an hour at 10 Hz)
MAX_SINCE = 2_000  # frames one frames.since call returns at most


class MountPacedClock:
    """Wait for mount times of a mount that runs by itself (real or ×speed time)."""

    def __init__(self, client: Client, names: dict[str, str] = EMULATOR_NAMES,
                 speed: float = 1.0) -> None:
        self.client = client
        self.name = names["mount_us"]
        self.speed = speed

    async def sleep_until_us(self, t_us: int) -> None:
        while True:
            now = int((await self.client.read([self.name]))[self.name])
            if now >= t_us:
                return
            await asyncio.sleep(max(0.001, (t_us - now) / 1e6 / self.speed * 0.9))


class GuideCameraDevice:
    """A simulated guide camera: truth + the mount's encoders -> centroid frames over ASTCom."""

    def __init__(self, connect: Callable[[], Awaitable[Client]], truth, *,
                 config: CameraConfig | None = None, site: CameraSite | None = None,
                 clock: Any = None, names: dict[str, str] | None = None,
                 passwords: dict[str, str] | None = None, speed: float = 1.0) -> None:
        self.config = config or CameraConfig()
        self.truth = truth
        self.site = site
        self.names = dict(names or EMULATOR_NAMES)
        self._connect = connect
        self._clock = clock
        self.speed = speed  # of a mount running by itself (without a lockstep clock)
        self.weather = Weather()
        self.frames: deque[Frame] = deque(maxlen=KEEP_FRAMES)
        self.last: Frame | None = None
        self.skipped = 0  # frames not taken because the camera fell behind the mount
        self.geometry = np.zeros(7)
        self._maker: FrameMaker | None = None
        self._client: Client | None = None
        self._task: asyncio.Task[None] | None = None
        self.collection = self._collection()
        self.endpoint = Endpoint(self.collection, EndpointConfig(
            loop_rate_hz=1.0 / self.config.period_s, passwords=passwords, name="guide-camera"))

    # ------------------------------------------------------------------ ASTCom
    def _collection(self) -> Collection:
        c = Collection()

        def last(attr: str, default: float = math.nan):
            return lambda: getattr(self.last, attr) if self.last is not None else default

        for name, attr, typ, unit, doc in (
                ("frame.seq", "seq", "i64", "", "Sequence number of the newest frame read out"),
                ("frame.t_us", "t_us", "i64", "us", "Middle of its exposure, mount time"),
                ("frame.ready_us", "ready_us", "i64", "us", "When it was read out, mount time"),
                ("frame.dx_arcsec", "dx_arcsec", "f64", "arcsec",
                 "Target minus optical axis along azimuth x cos(el) (NaN: nothing found)"),
                ("frame.dy_arcsec", "dy_arcsec", "f64", "arcsec",
                 "Target minus optical axis in elevation (NaN: nothing found)"),
                ("truth.dx_arcsec", "true_dx_arcsec", "f64", "arcsec",
                 "The true target's offset, noiseless (truth for tests; not a measurement)"),
                ("truth.dy_arcsec", "true_dy_arcsec", "f64", "arcsec",
                 "The true target's offset in elevation, noiseless (truth for tests)")):
            default = -1 if typ == "i64" else math.nan
            c.add_variable(name, typ, unit=unit, doc=doc, traced=True,
                           get=(lambda a=attr, d=default: int(getattr(self.last, a))
                                if self.last is not None else d) if typ == "i64"
                           else last(attr))
        c.add_variable("frame.found", "i64", doc="1 when the newest frame shows a target",
                       traced=True, get=lambda: int(self.last.found) if self.last else 0)
        c.add_variable("frame.why", "str", doc="Why the newest frame shows nothing (outside_field, "
                       "clouds, dropout) or ''", get=lambda: self.last.why if self.last else "")
        c.add_variable("camera.skipped_frames", "i64", doc="Frames not taken because the camera "
                       "fell behind the mount clock", get=lambda: self.skipped)
        c.add_variable("camera.period_s", "f64", unit="s", doc="Frame period (fixed at start)",
                       get=lambda: self.config.period_s)
        for field, unit, doc, lo, hi in (
                ("exposure_s", "s", "Exposure time", 1e-4, 60.0),
                ("readout_latency_s", "s", "From the end of an exposure to the frame's read-out",
                 0.0, 10.0),
                ("noise_arcsec", "arcsec", "1-sigma centroid noise per axis", 0.0, 100.0),
                ("fov_radius_arcsec", "arcsec", "Radius of the field of view", 1.0, 36000.0),
                ("dropout_fraction", "", "Fraction of frames lost at random", 0.0, 1.0)):
            c.add_variable(f"camera.{field}", "f64", kind="parameter", access="rw", unit=unit,
                           doc=doc, get=lambda f=field: float(getattr(self.config, f)),
                           set=lambda v, f=field: self._set(f, v), min_value=lo, max_value=hi)
        c.add_function("frames.since", self.frames_since, args=[("seq", "i64")], returns="str",
                       doc="Frames read out after sequence number seq (at most 2000), oldest "
                           "first, as a JSON list of {seq, t_us, ready_us, found, dx_arcsec, "
                           "dy_arcsec, why}")
        c.add_function("camera.add_clouds", self.add_clouds,
                       args=[("from_us", "i64"), ("to_us", "i64")],
                       doc="Clouds from one mount time to another: those frames show nothing")
        c.add_function("camera.add_impostor", self.add_impostor,
                       args=[("from_us", "i64"), ("to_us", "i64"), ("dx_arcsec", "f64"),
                             ("dy_arcsec", "f64")],
                       doc="Between two mount times the brightest object in the field is "
                           "another one, at (dx, dy) arcsec from the target")
        c.add_function("camera.clear_weather", self.clear_weather,
                       doc="Remove every scheduled cloud and impostor")
        c.add_function("camera.set_satellite", self.set_satellite,
                       args=[("line1", "str"), ("line2", "str")],
                       doc="Look for this satellite (its truth TLE) from the next frame on")
        c.add_function("camera.set_star", self.set_star,
                       args=[("ra_deg", "f64"), ("dec_deg", "f64")],
                       doc="Look for a star at this ICRS place (J2000, no proper motion)")
        return c

    def _set(self, field: str, value: float) -> None:
        try:
            self.config = dataclasses.replace(self.config, **{field: float(value)})
        except CameraConfigError as exc:
            raise ValueError(str(exc)) from None
        if self._maker is not None:
            self._maker.config = self.config

    def frames_since(self, seq: int) -> str:
        frames = self.frames
        if not frames:
            return "[]"
        # sequence numbers grow by one per frame kept (skipped ones are never stored)
        start = 0
        lo, hi = 0, len(frames)
        while lo < hi:  # first frame with seq > the one asked for
            mid = (lo + hi) // 2
            if frames[mid].seq > seq:
                hi = mid
            else:
                lo = mid + 1
        start = lo
        out = [frames[i].as_dict() for i in range(start, min(len(frames), start + MAX_SINCE))]
        return json.dumps(out, allow_nan=True)

    def add_clouds(self, from_us: int, to_us: int) -> None:
        if not to_us > from_us:
            raise ValueError("to_us must be after from_us")
        self.weather.clouds.append((int(from_us), int(to_us)))

    def add_impostor(self, from_us: int, to_us: int, dx_arcsec: float, dy_arcsec: float) -> None:
        if not to_us > from_us or not (math.isfinite(dx_arcsec) and math.isfinite(dy_arcsec)):
            raise ValueError("to_us must be after from_us and the offsets finite")
        self.weather.impostors.append((int(from_us), int(to_us), float(dx_arcsec),
                                       float(dy_arcsec)))

    def clear_weather(self) -> None:
        self.weather = Weather()

    def set_satellite(self, line1: str, line2: str) -> None:
        self._retarget(SatelliteTruth(line1, line2, self._need_site()))

    def set_star(self, ra_deg: float, dec_deg: float) -> None:
        self._retarget(StarTruth(ra_deg, dec_deg, self._need_site()))

    def _need_site(self) -> CameraSite:
        if self.site is None:
            raise ValueError("the camera was started without a site: it cannot compute a target")
        return self.site

    def _retarget(self, truth) -> None:
        self.truth = truth
        if self._maker is not None:
            self._maker.truth = truth

    # ------------------------------------------------------------------ running
    async def start(self, url: str | None = None) -> str:
        """Connect to the mount, serve ASTCom at `url` (None: in-memory only), start frames."""
        self._client = await self._connect()
        geometry = (await self._client.read([self.names["geometry"]]))[self.names["geometry"]]
        self.geometry = np.asarray(geometry, float)
        self._maker = FrameMaker(self.config, self.truth, self.geometry)
        if self._clock is None:
            self._clock = MountPacedClock(self._client, self.names, self.speed)
        bound = await self.endpoint.serve(url) if url is not None else ""
        self._task = asyncio.get_running_loop().create_task(self._run(), name="guide-camera")
        return bound

    async def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None
        await self.endpoint.close()
        if self._client is not None:
            with contextlib.suppress(Exception):
                await self._client.close()

    async def _read(self) -> tuple[int, int, float, float]:
        n = self.names
        v = await self._client.read([n["az"], n["el"], n["mount_us"], n["true_us"]])  # type: ignore[union-attr]
        return int(v[n["mount_us"]]), int(v[n["true_us"]]), float(v[n["az"]]), float(v[n["el"]])

    async def _run(self) -> None:
        period_us = int(round(self.config.period_s * 1e6))
        now = (await self._read())[0]
        first = (now // period_us + 1) * period_us
        seq = 0
        while True:
            cfg = self.config
            offsets = cfg.sample_offsets_us()
            t0 = first + seq * period_us
            now = (await self._read())[0]
            if now > t0 + int(offsets[0]):  # behind the mount (a slow host): skip ahead
                behind = (now - t0 - int(offsets[0])) // period_us + 1
                self.skipped += int(behind)
                seq += int(behind)
                continue
            rows = []
            for off in offsets:
                await self._clock.sleep_until_us(t0 + int(off))
                rows.append(await self._read())
            mount_us, true_us, az, el = (np.array(c) for c in zip(*rows, strict=True))
            try:
                frame = self._maker.frame(seq, mount_us, true_us, az, el, self.weather)  # type: ignore[union-attr]
            except Exception as exc:  # a truth that cannot be computed: report, go on
                log.warning("frame %d: %s", seq, exc)
                frame = Frame(seq, int(mount_us.mean()), int(mount_us[-1]), False, math.nan,
                              math.nan, f"no truth: {exc}")
            await self._clock.sleep_until_us(frame.ready_us)
            self.last = frame
            self.frames.append(frame)
            self.endpoint.publish(seq, frame.t_us, 1, None)
            seq += 1
