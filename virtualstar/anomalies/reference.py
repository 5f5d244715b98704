"""The reference: stretches where the mount is taken to behave as itself.

Every detector compares the night with what it saw on the reference, so a reference
must show the mount working: powered, past its settling, in the phases the night holds.

**Chosen automatically** (no `--reference`): from the window's start, the first
`length_s` (15 min) of *usable* time — segments with the mount powered, not settling,
without a recording gap — ending early at the first fault the mount or the VSS logged
(an `error` event of kind `fault`). Powered-off and settling time inside it is skipped,
not used. The rule looks only backwards, so live detection chooses the same reference
as `vs data anomalies` on the finished store.

**Refused** (ReferenceRefused, exit 2 in the CLI), given or automatic, when it
* holds the mount powered off (a given reference; the automatic one skips it): a
  powered-off axis has no current, error or spikes to learn from;
* holds less than `min_s` (5 min) of usable time;
* holds one motion phase only while the window spends `other_phase_share` (20 %) or more
  of its usable time in others (a reference of tracking only cannot say what a slew
  looks like).
Phases the reference holds less than `min_class_s` of are scored against a more dynamic
class, or not at all; the report says which (anomalies.detectors).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from virtualstar.recorder.exceptions import QueryError
from virtualstar.recorder.timeparse import utc_text

from .phases import MotionPhase

__all__ = ["Reference", "ReferenceConfig", "ReferenceRefused", "automatic_reference",
           "check_reference", "fault_times_us", "given_reference"]

MOVING = (MotionPhase.REST, MotionPhase.TRACKING, MotionPhase.SLEWING)


class ReferenceRefused(QueryError):
    """The reference cannot show the detectors the mount as usual; the message says why
    and what to give instead."""


@dataclass(frozen=True)
class ReferenceConfig:
    length_s: float = 900.0
    min_s: float = 300.0  # a few of the longest detector windows (temperature: 120 s)
    min_class_s: float = 20.0
    other_phase_share: float = 0.2


@dataclass
class Reference:
    """The reference stretches (mount µs, half-open) and what they hold."""

    stretches: list[tuple[int, int]]
    how: str  # "automatic" or "given"
    usable_s: float = 0.0
    phase_s: dict[str, float] = field(default_factory=dict)

    def mask(self, t_first_us: np.ndarray, t_last_us: np.ndarray) -> np.ndarray:
        """True for the segments inside a stretch."""
        out = np.zeros(len(t_first_us), bool)
        for a, b in self.stretches:
            out |= (t_first_us >= a) & (t_last_us < b)
        return out

    def as_dict(self) -> dict[str, object]:
        return {"how": self.how, "usable_s": round(self.usable_s, 1),
                "stretches": [{"start_utc": utc_text(a), "end_utc": utc_text(b),
                               "start_t_us": a, "end_t_us": b} for a, b in self.stretches],
                "phases_s": {k: round(v, 1) for k, v in self.phase_s.items()}}


def usable(phase: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Segments a reference can learn from: powered, not settling, no recording gap."""
    return valid & (phase != MotionPhase.OFF) & (phase != MotionPhase.SETTLING)


def fault_times_us(events) -> np.ndarray:
    """Mount times of the faults the mount or the VSS logged (error-level `fault`)."""
    return np.sort(np.asarray([int(e.t_us) for e in events
                               if e.kind == "fault" and e.level == "error"], dtype=np.int64))


def _seconds(t_first: np.ndarray, t_last: np.ndarray, rows: np.ndarray) -> float:
    return float(np.sum(t_last[rows] - t_first[rows])) * 1e-6


def _phase_seconds(t_first, t_last, phase, rows) -> dict[str, float]:
    return {p.label: _seconds(t_first, t_last, rows & (phase == p)) for p in MOVING
            if (rows & (phase == p)).any()}


def automatic_reference(t_first: np.ndarray, t_last: np.ndarray, phase: np.ndarray,
                        valid: np.ndarray, faults_us: np.ndarray,
                        config: ReferenceConfig) -> tuple[Reference, bool]:
    """Return the automatic reference over the segments so far and whether it is complete
    (it reached `length_s` of usable time, or a fault ended it)."""
    use = usable(phase, valid)
    if not use.any():
        return Reference([], "automatic"), False
    first = int(np.argmax(use))
    start_us = int(t_first[first])
    later = faults_us[faults_us >= start_us]
    fault_us = int(later[0]) if len(later) else None
    span = np.where(use, t_last - t_first, 0) * 1e-6
    held = np.cumsum(span)
    inside = use & (held <= config.length_s)
    if fault_us is not None:
        inside &= t_last < fault_us
    last = int(np.flatnonzero(inside)[-1]) if inside.any() else first
    complete = bool(held[-1] >= config.length_s) or (
        fault_us is not None and int(t_last[-1]) >= fault_us)
    ref = Reference([(start_us, int(t_last[last]) + 1)], "automatic")
    rows = inside & (t_first >= start_us)
    ref.usable_s = _seconds(t_first, t_last, rows)
    ref.phase_s = _phase_seconds(t_first, t_last, phase, rows)
    return ref, complete


def given_reference(stretches: list[tuple[int, int]], t_first: np.ndarray,
                    t_last: np.ndarray, phase: np.ndarray, valid: np.ndarray) -> Reference:
    """Return the reference of `--reference` stretches, refusing one that holds the mount
    powered off."""
    ref = Reference(sorted(stretches), "given")
    inside = ref.mask(t_first, t_last)
    off = inside & (phase == MotionPhase.OFF)
    if off.any():
        a, b = int(t_first[off][0]), int(t_last[off][-1])
        raise ReferenceRefused(
            f"the reference holds the mount powered off ({_seconds(t_first, t_last, off):.0f} s "
            f"between {utc_text(a)} and {utc_text(b)}): a powered-off axis has no current, "
            "error or spikes to learn from; give --reference stretches with the mount "
            "working, or none (the first 15 minutes of working time are taken)")
    rows = inside & usable(phase, valid)
    ref.usable_s = _seconds(t_first, t_last, rows)
    ref.phase_s = _phase_seconds(t_first, t_last, phase, rows)
    return ref


def check_reference(ref: Reference, window_phase_s: dict[str, float] | None,
                    config: ReferenceConfig) -> None:
    """Raise ReferenceRefused when `ref` is too short, or holds one phase only while the
    window (its usable seconds per phase, when known) spends much time in others."""
    where = ", ".join(f"{utc_text(a)}..{utc_text(b)}" for a, b in ref.stretches) or "(none)"
    if ref.usable_s < config.min_s:
        raise ReferenceRefused(
            f"the {ref.how} reference {where} holds {ref.usable_s:.0f} s of the mount working "
            f"(powered, past its settling, without gaps); the detectors need "
            f"{config.min_s:.0f} s or more: give --reference FROM..TO over a longer stretch")
    held = [p for p, s in ref.phase_s.items() if s >= config.min_class_s]
    if len(held) != 1 or not window_phase_s:
        return
    total = sum(window_phase_s.values())
    others = {p: s for p, s in window_phase_s.items() if p != held[0] and s > 0}
    if total > 0 and sum(others.values()) >= config.other_phase_share * total:
        seen = ", ".join(f"{p} {s:.0f} s" for p, s in sorted(others.items()))
        raise ReferenceRefused(
            f"the {ref.how} reference {where} holds one motion phase only ({held[0]}, "
            f"{ref.phase_s[held[0]]:.0f} s) while the window also holds {seen}: the "
            "detectors cannot learn from it what the other phases look like; give "
            "--reference stretches that hold slews and tracking")
