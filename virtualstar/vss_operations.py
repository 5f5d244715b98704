"""What a VSS operation object (docs/vss-api.md, "Operation object") says about the telescope.

The Alpaca and INDI façades mirror the telescope's state from the VSS's current operation
instead of remembering what they asked for; these are the readings both make.
"""

from __future__ import annotations

from typing import Any

__all__ = ["ENDED_PHASES", "MOVING_PHASES", "hand_pad_rates", "is_moving", "is_parked",
           "is_tracking"]

ENDED_PHASES = frozenset({"done", "failed", "aborted"})
MOVING_PHASES = frozenset({"starting", "preparing", "slewing", "joining", "settling",
                           "interrupted", "ending", "waiting"})
TRACKING_KINDS = frozenset({"slew", "track", "track_satellite"})

Op = dict[str, Any] | None


def is_tracking(op: Op) -> bool:
    """A sky target is being followed (a held az/el, `info.fixed`, is not)."""
    return (op is not None and op["kind"] in TRACKING_KINDS and op["phase"] not in ENDED_PHASES
            and not op["info"].get("fixed"))


def is_moving(op: Op) -> bool:
    """The operation is moving the mount towards where it goes (a hand-pad move until it
    ends; a satellite held for a pass that has not risen is not moving)."""
    if op is None:
        return False
    if op["kind"] == "move":
        return op["phase"] not in ENDED_PHASES
    if op["kind"] == "track_satellite" and op["phase"] in ("waiting", "pass planned"):
        return False
    return op["phase"] in MOVING_PHASES


def is_parked(op: Op, released_id: int | None) -> bool:
    """The park operation is done and no unpark has released it since."""
    return (op is not None and op["kind"] == "park" and op["phase"] == "done"
            and op["id"] != released_id)


def hand_pad_rates(op: Op) -> list[float]:
    """The axis rates (deg/s) of a running `move`, else zero."""
    if op is None or op["kind"] != "move" or op["phase"] in ENDED_PHASES:
        return [0.0, 0.0]
    return [float(op["info"].get("az_rate_deg_s", 0.0)),
            float(op["info"].get("el_rate_deg_s", 0.0))]
