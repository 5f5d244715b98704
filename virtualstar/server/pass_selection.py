"""Which satellite pass to track, and from when: a pure decision over predicted passes.

A pass is worth joining if, after the mount has had time to get there, at least
`min_track_s` of it remain above the horizon limit. A pass already in progress
(its rise before now, or before the search began) is joined as soon as the mount
can reach the satellite: before or after culmination alike. The time needed to
get there depends on where the satellite will be, so the caller gives it as a
function of the join instant.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass

__all__ = ["PassChoice", "PassWindow", "choose_pass", "windows_from_passes"]

DEFAULT_MIN_TRACK_S = 30.0
_REFINE_ROUNDS = 3  # the prepare time depends on the join, which depends on the prepare time


@dataclass(frozen=True)
class PassWindow:
    """One predicted pass above the limit, mount time µs.

    rise_us is None when the satellite was already above the limit where the
    prediction began; set_us None when the pass ends beyond the prediction.
    """

    rise_us: int | None
    set_us: int | None
    culmination_us: int
    culmination_el_deg: float


@dataclass(frozen=True)
class PassChoice:
    """The pass chosen and the mount time at which the trajectory joins it."""

    window: PassWindow
    join_us: int
    in_progress: bool  # joined after its rise (later than the rise, or already risen)

    @property
    def remaining_s(self) -> float:
        assert self.window.set_us is not None
        return (self.window.set_us - self.join_us) / 1e6


def windows_from_passes(passes: Iterable) -> list[PassWindow]:
    """Convert `virtualstar.astro.satellite_passes` results into mount-time windows."""
    out = []
    for p in passes:
        out.append(PassWindow(
            rise_us=int(p.rise.utc.to_unix_us()[0]) if p.rise is not None else None,
            set_us=int(p.set.utc.to_unix_us()[0]) if p.set is not None else None,
            culmination_us=int(p.culmination.utc.to_unix_us()[0]),
            culmination_el_deg=float(p.culmination.el_deg)))
    return out


def choose_pass(windows: Iterable[PassWindow], now_us: int, *,
                prepare_s: Callable[[int], float],
                min_track_s: float = DEFAULT_MIN_TRACK_S) -> PassChoice | None:
    """Return the first pass that can still be tracked for `min_track_s`, or None.

    prepare_s(join_us): mount seconds needed from now before the path can be joined
    at `join_us` (slew to where the satellite is then, run-up, margins). A pass
    whose set is unknown (beyond the prediction) is skipped: it cannot be planned.
    """
    for w in sorted(windows, key=lambda w: w.culmination_us):
        if w.set_us is None or w.set_us <= now_us:
            continue
        start = now_us if w.rise_us is None else max(w.rise_us, now_us)
        join = start
        for _ in range(_REFINE_ROUNDS):
            join = max(start, now_us + int(prepare_s(join) * 1e6))
        if w.set_us - join >= min_track_s * 1e6:
            in_progress = w.rise_us is None or join > w.rise_us
            return PassChoice(w, join, in_progress)
    return None
