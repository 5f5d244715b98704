"""Steer the running track: offsets (PWI4-style), guide pulses, and their status.

The `Telescope` owns one `Steering`; it hands each sky or satellite track its own
`Corrections` (corrections.py), so a new operation — and `stop` — starts with no
offset at all. Commands check their values here (ranges in the messages) before
anything reaches the supervisor's operation.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from virtualstar.astro import iso_utc

from .camera_link import CameraLink
from .corrections import CorrectionMode, Corrections
from .estimator import FilterConfig
from .exceptions import BadRequest, NoCamera, NotTracking
from .guiding import MAX_GUIDE_RATE_ARCSEC_S, MAX_GUIDE_STEP_ARCSEC, pulse_change
from .hand_pad import HandPad
from .offsets import AXES, OPERATIONS, OffsetLimits
from .operations import TERMINAL, Operation, Phase

if TYPE_CHECKING:
    from .telescope import Telescope

__all__ = ["MAX_OFFSET_ARCSEC", "MAX_PATH_S", "Steering"]

MAX_OFFSET_ARCSEC = 3600.0  # an offset moves the boresight at most 1° (slew beyond)
MAX_PATH_S = 30.0  # along-track offsets up to ±30 s (a TLE that far off: load fresh ones)
MAX_PATH_RATE = 1.0  # s per s: the boresight at most twice as fast as the target
STEERABLE = ("slew", "track", "track_satellite")
DEFAULT_MIN_LEAD_US = 20_000  # a controller with replace_from but no lead signal
MARGIN_PER_SPEED_US = 10_000  # a request's travel to the mount, real time (× speed)


class Steering:
    """Offsets and guide pulses of the operation in progress."""

    def __init__(self, telescope: Telescope) -> None:
        self.t = telescope
        cfg = telescope.config
        if not (0 < cfg.offset_rate_arcsec_s <= 36000 and 0 < cfg.offset_accel_arcsec_s2 <= 36000):
            raise BadRequest("offset limits: rate and acceleration must be > 0 and at most "
                             "36000″/s (10°/s) and 36000″/s²")
        self.limits = OffsetLimits(cfg.offset_rate_arcsec_s, cfg.offset_accel_arcsec_s2)
        self.min_lead_us = DEFAULT_MIN_LEAD_US
        self._current: tuple[int, Corrections] | None = None
        self._pad: tuple[int, HandPad] | None = None  # the running move's (hand_pad.py)
        self.camera: CameraLink | None = None  # a guide camera for closed loops (camera_link.py)
        self.filter_config = FilterConfig()

    @property
    def mode(self) -> CorrectionMode:
        link, clock = self.t.link, self.t.clock
        margin = 0 if clock.lockstep else int(MARGIN_PER_SPEED_US * max(1.0, clock.speed))
        caps = link.capabilities
        return CorrectionMode(link.mapping.has_function("traj_replace"), self.min_lead_us,
                              margin, rate_loop=caps.rate_axes and not caps.trajectory_buffer)

    def corrections(self, op: Operation) -> Corrections:
        """The offsets of a track (kept through its re-acquisitions, new for a new operation)."""
        if self._current is None or self._current[0] != op.id:
            self._current = (op.id, Corrections(self.mode, self.t.motion.mount_time_us,
                                                math.radians(self.t.config.site.lat_deg),
                                                limits=self.limits))
        return self._current[1]

    def hand_pad(self, op: Operation | None) -> HandPad | None:
        """The hand pad of a running move, None for any other operation."""
        if op is None or op.finished or self._pad is None or self._pad[0] != op.id:
            return None
        return self._pad[1]

    def keep_hand_pad(self, op: Operation, pad: HandPad) -> None:
        """Remember the pad of a move just started (a move that took new rates keeps its own)."""
        if self.hand_pad(op) is None:
            self._pad = (op.id, pad)

    def need_camera(self, what: str) -> None:
        """Refuse a closed loop without a guide camera (NoCamera, naming the option)."""
        if self.camera is None:
            raise NoCamera(f"{what}: closed-loop tracking needs a guide camera: start the server "
                           "with --camera URL (or the embedded emulator's simulated camera, "
                           "--camera-sim); open-loop tracking needs none")

    def running(self, what: str) -> tuple[Operation, Corrections]:
        """The operation a correction applies to; NotTracking when there is none."""
        op = self.t.op
        if (op is None or op.kind not in STEERABLE or op.info.get("fixed")
                or op.phase in TERMINAL or op.phase is Phase.ENDING):
            state = "nothing runs" if op is None else \
                f"operation {op.id} ({op.kind}) is {op.phase.label}"
            raise NotTracking(f"{what}: no sky target or satellite is being tracked ({state}); "
                              "offsets and guide pulses apply to a running track or slew of "
                              "a star, planet, RA/Dec or satellite")
        return op, self.corrections(op)

    # ------------------------------------------------------------------ commands
    async def offset(self, axis: str, operation: str, *, arcsec: float | None = None,
                     seconds: float | None = None) -> dict[str, Any]:
        """Apply a PWI4-style offset to the running track (docs/vss-api.md, `offset`)."""
        axes = AXES if axis == "all" else (axis,)
        check_offset(axis, operation, arcsec, seconds, self.limits)
        op, corr = self.running("offset")
        change = _offset_change(axes, operation, arcsec, seconds)
        record = await corr.apply(f"offset {axis} {operation}", change)
        if self.t.op is not op:
            raise NotTracking(f"offset: operation {op.id} ended while the offset was sent")
        doc = self._answer(op, corr, record)
        asked = {"axis": axis, "op": operation,
                 **{k: v for k, v in (("arcsec", arcsec), ("seconds", seconds)) if v is not None}}
        self._log(op, f"offset {axis} {operation}"
                  + ("" if operation == "reset" else f" {_value_text(axis, arcsec, seconds)}"),
                  doc, asked)
        return doc

    async def guide(self, north_arcsec: float, east_arcsec: float,
                    rate_arcsec_s: float) -> dict[str, Any]:
        """A guide pulse on the running track: north/east at `rate_arcsec_s`."""
        check_guide(north_arcsec, east_arcsec, rate_arcsec_s)
        op, corr = self.running("guide")
        record = await corr.apply("guide pulse",
                                  pulse_change(north_arcsec, east_arcsec, rate_arcsec_s))
        if self.t.op is not op:
            raise NotTracking(f"guide: operation {op.id} was replaced while the pulse was "
                              "being scheduled")
        doc = self._answer(op, corr, record)
        doc.update({"start_us": record["from_us"], "end_us": record["reached_us"],
                    "start_utc": iso_utc(record["from_us"], 3),
                    "end_utc": iso_utc(record["reached_us"], 3)})
        goal = doc["offsets"]["axes"]
        doc["offset_arcsec"] = {"north": goal.get("dec", {}).get("goal_arcsec", 0.0),
                                "east": goal.get("ra", {}).get("goal_arcsec", 0.0)}
        return doc

    async def close(self) -> None:
        if self.camera is not None:
            await self.camera.close()

    # ------------------------------------------------------------------ status
    def status(self, t_us: int | None) -> dict[str, Any]:
        """`status`'s "corrections": how they reach the mount and the current offsets."""
        doc: dict[str, Any] = self.mode.as_dict()
        doc["camera"] = None if self.camera is None else self.camera.config.url
        op = self.t.op
        if (self._current is not None and op is not None and self._current[0] == op.id
                and op.phase not in TERMINAL and t_us is not None):
            doc["offsets"] = self._current[1].status(t_us)
        return doc

    def _answer(self, op: Operation, corr: Corrections, record: dict[str, Any]) -> dict[str, Any]:
        return {"id": op.id, **record, "from_utc": iso_utc(record["from_us"], 3),
                "reached_utc": iso_utc(record["reached_us"], 3), "mode": self.mode.as_dict()["mode"],
                "offsets": corr.status(record["from_us"])}

    def _log(self, op: Operation, text: str, doc: dict[str, Any],
             asked: dict[str, Any]) -> None:
        """Log and push an offset: what was asked (axis, op, arcsec or seconds), and when and
        how it reaches the mount."""
        fields = {"id": op.id, **asked, "from_us": doc["from_us"], "lead_ms": doc["lead_ms"],
                  "sent": doc["sent"]}
        self.t.log_event("info", "offset", f"operation {op.id}: {text} (from "
                         f"{doc['from_utc']}, {doc['lead_ms']:.0f} ms after acceptance, "
                         f"{doc['sent']})", **fields)
        self.t.emit("offset", {**fields, "text": text})


def check_offset(axis: str, operation: str, arcsec: float | None, seconds: float | None,
                 limits: OffsetLimits) -> None:
    """Refuse an offset command whose axis, operation or value is not allowed (BadRequest)."""
    if axis not in (*AXES, "all"):
        raise BadRequest(f"offset: axis {axis!r}: expected one of {', '.join(AXES)} (or 'all' "
                         "with op=reset)")
    if operation not in OPERATIONS:
        raise BadRequest(f"offset: op {operation!r}: expected one of {', '.join(OPERATIONS)}")
    if axis == "all" and operation != "reset":
        raise BadRequest("offset: axis 'all' goes only with op=reset")
    if operation == "reset":
        if arcsec is not None or seconds is not None:
            raise BadRequest("offset: op=reset takes no value")
        return
    if (arcsec is None) == (seconds is None):
        raise BadRequest(f"offset {axis} {operation}: give exactly one of arcsec or seconds")
    if seconds is not None and axis != "path":
        raise BadRequest(f"offset {axis}: seconds (of time) are for the path axis only; "
                         f"{axis} takes arcsec")
    rate = operation == "rate"
    for value, name in ((arcsec, "arcsec"), (seconds, "seconds")):
        if value is not None and not math.isfinite(value):
            raise BadRequest(f"offset: {name}={value!r} must be a finite number")
    if arcsec is not None:
        top = limits.rate_arcsec_s if rate else MAX_OFFSET_ARCSEC
        if abs(arcsec) > top:
            unit = "arcsec/s" if rate else "arcsec"
            raise BadRequest(f"offset {axis} {operation}: arcsec={arcsec:g} is beyond ±{top:g} "
                             f"{unit}" + ("" if rate else "; slew instead"))
    if seconds is not None:
        top = MAX_PATH_RATE if rate else MAX_PATH_S
        if abs(seconds) > top:
            raise BadRequest(f"offset path {operation}: seconds={seconds:g} is beyond ±{top:g} "
                             + ("s per s" if rate else "s (load fresh elements instead)"))


def check_guide(north_arcsec: float, east_arcsec: float, rate_arcsec_s: float) -> None:
    if not 0 < rate_arcsec_s <= MAX_GUIDE_RATE_ARCSEC_S:
        raise BadRequest(f"guide: rate_arcsec_s={rate_arcsec_s:g}: expected > 0 and at most "
                         f"{MAX_GUIDE_RATE_ARCSEC_S:g} (ten times sidereal)")
    size = math.hypot(north_arcsec, east_arcsec)
    if size == 0.0:
        raise BadRequest("guide: north_arcsec and east_arcsec are both 0")
    if size > MAX_GUIDE_STEP_ARCSEC:
        raise BadRequest(f"guide: a pulse of {size:g}\u2033 is beyond the "
                         f"{MAX_GUIDE_STEP_ARCSEC:g}\u2033 a guide pulse may move; slew instead")


def _offset_change(axes: tuple[str, ...], operation: str, arcsec: float | None,
                   seconds: float | None):
    def change(offsets, from_us: int, sky_rate: float | None) -> int:
        reached = from_us
        for axis in axes:
            value = 0.0
            if operation != "reset":
                value = seconds if seconds is not None else float(arcsec)  # type: ignore[arg-type]
                if axis == "path" and seconds is None:
                    # arcsec along the track: seconds at the target's rate where it starts
                    if not sky_rate:
                        raise NotTracking("offset path in arcsec: the target does not move "
                                          "here; give seconds")
                    value = value / sky_rate
            if axis in ("path", "transverse") and operation != "reset" and not sky_rate:
                raise NotTracking(f"offset {axis}: the target's direction of travel is not "
                                  "known yet (no path); try again once it is tracked")
            reached = max(reached, offsets.change(axis, operation, value, from_us,
                                                  sky_rate_arcsec_s=sky_rate))
        return reached

    return change


def _value_text(axis: str, arcsec: float | None, seconds: float | None) -> str:
    if seconds is not None:
        return f"{seconds:+g} s"
    return f"{arcsec:+g}\u2033"

