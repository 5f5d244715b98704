"""What the mount was doing in each segment: its motion phase, and per axis its speed regime.

A night holds slews, settling after them, sidereal tracks, satellite passes at up to a
few degrees per second, waits at rest and stretches with the mount powered off. The
current and the tracking error look different in each, so the detectors model them per
**class** (phase × speed regime, per axis) and never mix classes in one window.

Phases come from, in this order of precedence for each segment:

1. the mount's `state` events (the emulator and any ASTCom device that serves
   `log.since`, stamped to the controller's block): OFF and FAULT (powered off), HOLDING
   (at rest), SLEWING, STOPPING and MANUAL (slewing), TRACKING (following a trajectory:
   a star, a satellite, a run-up);
2. the VSS's `phase` events in the store (`vs run --record`, `vs record --vss-log`;
   stamped to its newest tracking-error sample, within about a second): slewing and
   ending (slewing), waiting (at rest), tracking and measuring (tracking); the VSS's
   settling phase counts as settling even where the mount's state says tracking;
   joining (a run-up: the mount holds, then follows a gentle trajectory) and the
   phases around an operation's start and end say nothing by themselves;
3. the signals: slewing when an axis accelerates faster than `slew_accel_deg_s2` or
   turns faster than `slew_rate_deg_s`, at rest when every axis turns slower than
   `rest_rate_arcsec_s`, tracking otherwise. Without events a satellite pass's fastest
   moments (near the zenith) can read as slewing.

Powered off is also read from the signals whatever the events say (a power cut logs
nothing): every recorded current within `off_current_a` of zero, without a one-sample
jump. **Settling**: the first `settle_s` after a slew ends or the mount is powered on
are settling, whatever the source (the loops' integrators unwind, the structure rings
down); the detectors leave them out of the reference and of the scoring.

Labelling is causal — a segment's phase depends only on the segments and events before
it (and its own) — so live detection labels a night exactly as `vs data anomalies` does.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import numpy as np

from .segments import Segments

__all__ = ["AXIS_CLASSES", "CLASS_NAMES", "EXCLUDED", "FAST", "FASTER", "REST", "SLEW", "SLOW",
           "MotionPhase", "PhaseConfig", "PhaseLabeller", "axis_classes"]


class MotionPhase(enum.IntEnum):
    """What the mount is doing; `label` is the name reports use."""

    OFF = 0
    REST = 1
    TRACKING = 2
    SLEWING = 3
    SETTLING = 4

    @property
    def label(self) -> str:
        return _PHASE_LABELS[self]


_PHASE_LABELS = {MotionPhase.OFF: "powered off", MotionPhase.REST: "at rest",
                 MotionPhase.TRACKING: "tracking", MotionPhase.SLEWING: "slewing",
                 MotionPhase.SETTLING: "settling"}

# Per axis, the class a detector models: the phase, and while tracking, the axis's speed.
EXCLUDED = -1  # powered off or settling: neither reference nor scored
REST, SLOW, FAST, FASTER, SLEW = 0, 1, 2, 3, 4
AXIS_CLASSES = (REST, SLOW, FAST, FASTER, SLEW)  # from the quietest to the loudest
CLASS_NAMES = {REST: "at rest", SLOW: "tracking at sidereal rates (< 0.2°/s)",
               FAST: "tracking at satellite rates (0.2–1°/s)",
               FASTER: "tracking at satellite rates (≥ 1°/s)", SLEW: "slewing"}

# The VSS's operation phases (virtualstar/server/operations.py, their labels) and the
# mount states (mount.state_name) as motion phases; None: this source does not say.
VSS_PHASES: dict[str, MotionPhase | None] = {
    "slewing": MotionPhase.SLEWING, "joining": None,
    "ending": MotionPhase.SLEWING, "waiting": MotionPhase.REST,
    "settling": MotionPhase.SETTLING, "tracking": MotionPhase.TRACKING,
    "measuring": MotionPhase.TRACKING,
    # the previous motion goes on (or the mount is being stopped) until the next phase
    "starting": None, "preparing": None, "pass planned": None, "interrupted": None,
    "done": None, "failed": None, "aborted": None,
}
MOUNT_STATES: dict[str, MotionPhase | None] = {
    "OFF": MotionPhase.OFF, "FAULT": MotionPhase.OFF, "HOLDING": MotionPhase.REST,
    "SLEWING": MotionPhase.SLEWING, "STOPPING": MotionPhase.SLEWING,
    "MANUAL": MotionPhase.SLEWING, "TRACKING": MotionPhase.TRACKING,
}


@dataclass(frozen=True)
class PhaseConfig:
    """Limits of the phases read from the signals, the settle time and the speed regimes.

    settle_s: measured after the 6°/s slews of four clean VSS nights on the emulator
    (docs/anomalies.md, "Settling"): the tracking error's loudest band is ×10⁵ its usual
    power in the first second after a slew, ×26 at 3–5 s, ×3 at 5–7 s and ×2 at 7–10 s
    (the flagging floor is ×16); 10 s.
    fast_rate_deg_s: tracking faster than this on an axis is "satellite rates": sidereal
    tracking stays below it except within 1.5° of the zenith. faster_rate_deg_s: above it
    the error's spectrum and its jumps where the trajectory's pieces meet grow with the
    rate (a pass near the zenith), so it is a regime of its own.
    """

    settle_s: float = 10.0
    slew_rate_deg_s: float = 3.0
    slew_accel_deg_s2: float = 0.2
    rest_rate_arcsec_s: float = 1.0
    off_current_a: float = 0.002
    fast_rate_deg_s: float = 0.2
    faster_rate_deg_s: float = 1.0


def _timeline(events, source: str, table: dict[str, MotionPhase | None],
              field: str) -> tuple[np.ndarray, np.ndarray]:
    """Return (times µs, phase codes; -1 = this source does not say) of `source`'s events."""
    t, code = [], []
    for e in events:
        if e.source != source or e.kind != ("phase" if source == "vss" else "state"):
            continue
        name = e.fields.get(field)
        if not isinstance(name, str) or name not in table:
            continue
        phase = table[name]
        t.append(int(e.t_us))
        code.append(-1 if phase is None else int(phase))
    order = np.argsort(np.asarray(t, dtype=np.int64), kind="stable")
    return (np.asarray(t, dtype=np.int64)[order], np.asarray(code, dtype=np.int64)[order])


def _at(times: np.ndarray, codes: np.ndarray, t_us: np.ndarray) -> np.ndarray:
    """The code in force at each `t_us` (-1 before the first event)."""
    if len(times) == 0:
        return np.full(len(t_us), -1, dtype=np.int64)
    k = np.searchsorted(times, t_us, side="right") - 1
    return np.where(k >= 0, codes[np.maximum(k, 0)], -1)


class PhaseLabeller:
    """Label segments with motion phases, chunk after chunk (causal; see the module doc).

    `axes` maps each axis to its recorded roles (segments.axis_signals). Events can be
    given at once or added as they come (`add_events`); a chunk must be labelled only
    once the events up to its end are in.
    """

    def __init__(self, axes: dict[str, dict[str, str]], events=(), *,
                 config: PhaseConfig | None = None) -> None:
        self.axes = axes
        self.config = config or PhaseConfig()
        self._events: list = []
        self._vss = self._mount = (np.zeros(0, np.int64), np.zeros(0, np.int64))
        self._settle_until_us: int | None = None
        self._previous = -1
        self.seconds = {p: 0.0 for p in MotionPhase}
        self.add_events(events)

    @property
    def source(self) -> str:
        """Where the phases came from, for the report."""
        found = [name for name, tl in (("the mount's state events", self._mount),
                                       ("the VSS's phase events", self._vss)) if len(tl[0])]
        if found:
            return " and ".join(found) + " (the signals where they say nothing)"
        if any("position" in roles for roles in self.axes.values()):
            return "the signals (speed, acceleration, current)"
        return "none: no position signal and no events; every segment counted as tracking"

    def add_events(self, events) -> None:
        new = [e for e in events if (e.source, e.kind) in (("vss", "phase"),
                                                          ("emulator", "state"))
               or (e.kind == "state" and "new" in e.fields)]
        if not new:
            return
        self._events += new
        self._vss = _timeline(self._events, "vss", VSS_PHASES, "phase")
        mount = [e for e in self._events if e.kind == "state" and e.source != "vss"]
        t, code = [], []
        for e in sorted(mount, key=lambda e: e.t_us):
            name = e.fields.get("new")
            if isinstance(name, str) and name in MOUNT_STATES:
                phase = MOUNT_STATES[name]
                t.append(int(e.t_us))
                code.append(-1 if phase is None else int(phase))
        self._mount = (np.asarray(t, dtype=np.int64), np.asarray(code, dtype=np.int64))

    def _from_signals(self, seg: Segments) -> np.ndarray:
        cfg = self.config
        f = seg.features
        n = len(seg)
        slew = np.zeros(n, bool)
        rest = np.ones(n, bool)
        moving_known = False
        for ax in self.axes:
            v = f.get(f"{ax}.velocity_rad_s")
            if v is None:
                continue
            moving_known = True
            a = f[f"{ax}.acceleration_rad_s2"]
            slew |= (np.abs(a) > math.radians(cfg.slew_accel_deg_s2)) | \
                (np.abs(v) > math.radians(cfg.slew_rate_deg_s))
            rest &= np.abs(v) < math.radians(cfg.rest_rate_arcsec_s / 3600.0)
        if not moving_known:
            return np.full(n, int(MotionPhase.TRACKING), dtype=np.int64)
        return np.where(slew, int(MotionPhase.SLEWING),
                        np.where(rest, int(MotionPhase.REST), int(MotionPhase.TRACKING)))

    def _off_from_signals(self, seg: Segments) -> np.ndarray:
        f = seg.features
        off = np.ones(len(seg), bool)
        known = False
        for ax in self.axes:
            i = f.get(f"{ax}.current_a")
            if i is None:
                continue
            known = True
            off &= (np.abs(i) < self.config.off_current_a) & \
                (f[f"{ax}.current_spike_a"] < self.config.off_current_a)
        return off if known else np.zeros(len(seg), bool)

    def label(self, seg: Segments) -> np.ndarray:
        """Return the MotionPhase code of each segment of the chunk (int64)."""
        n = len(seg)
        if n == 0:
            return np.zeros(0, np.int64)
        t = seg.t_mid_us
        phase = self._from_signals(seg)
        vss = _at(*self._vss, t)
        phase = np.where(vss >= 0, vss, phase)
        mount = _at(*self._mount, t)
        phase = np.where(mount >= 0, mount, phase)
        phase = np.where(vss == int(MotionPhase.SETTLING), int(MotionPhase.SETTLING), phase)
        phase = np.where((mount == int(MotionPhase.OFF)) | self._off_from_signals(seg),
                         int(MotionPhase.OFF), phase)
        out = self._settle(phase, seg.t_first_us)
        for p in MotionPhase:
            self.seconds[p] += float(np.sum(seg.t_last_us[out == p] - seg.t_first_us[out == p]
                                            )) * 1e-6
        return out

    def _settle(self, phase: np.ndarray, t_first: np.ndarray) -> np.ndarray:
        """Mark `settle_s` after each end of a slew or power-off as settling (a loop: the
        settle window restarts at every such end; chunks carry it on)."""
        settle_us = round(self.config.settle_s * 1e6)
        out = phase.copy()
        moved = (phase == MotionPhase.SLEWING) | (phase == MotionPhase.OFF)
        prev = np.r_[self._previous, phase[:-1]]
        prev_moved = (prev == MotionPhase.SLEWING) | (prev == MotionPhase.OFF)
        ends = np.flatnonzero(prev_moved & ~moved & (prev >= 0))
        until = np.full(len(phase), np.iinfo(np.int64).min, dtype=np.int64)
        if self._settle_until_us is not None:
            until[:] = self._settle_until_us
        for k in ends:  # few per chunk: one per slew
            until[k:] = t_first[k] + settle_us
        calm = (phase == MotionPhase.REST) | (phase == MotionPhase.TRACKING)
        out[calm & (t_first < until)] = int(MotionPhase.SETTLING)
        self._settle_until_us = int(until[-1]) if until[-1] > np.iinfo(np.int64).min else None
        self._previous = int(phase[-1])
        return out


def axis_classes(phase: np.ndarray, velocity_rad_s: np.ndarray | None,
                 config: PhaseConfig, acceleration_rad_s2: np.ndarray | None = None
                 ) -> np.ndarray:
    """Return each segment's class on one axis (REST, SLOW, FAST, FASTER, SLEW, EXCLUDED).

    While the mount slews, an axis that does not move (the other one slews alone) is
    neither slewing nor settled — it has often just stopped — and is left out."""
    out = np.full(len(phase), EXCLUDED, dtype=np.int64)
    out[phase == MotionPhase.REST] = REST
    slewing = phase == MotionPhase.SLEWING
    if velocity_rad_s is not None and acceleration_rad_s2 is not None:
        still = (np.abs(velocity_rad_s) < math.radians(config.rest_rate_arcsec_s / 3600.0)) & \
            (np.abs(acceleration_rad_s2) < math.radians(config.slew_accel_deg_s2))
        slewing &= ~still
    out[slewing] = SLEW
    tracking = phase == MotionPhase.TRACKING
    if velocity_rad_s is None:
        out[tracking] = SLOW
    else:
        speed = np.abs(velocity_rad_s)
        fast = speed >= math.radians(config.fast_rate_deg_s)
        faster = speed >= math.radians(config.faster_rate_deg_s)
        out[tracking & ~fast] = SLOW
        out[tracking & fast & ~faster] = FAST
        out[tracking & faster] = FASTER
    return out
