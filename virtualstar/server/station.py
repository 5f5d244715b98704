"""What the procedures and the program runner may use of the server: a named, narrow view.

`procedures.py` and `programs.py` take a `Station`, not the whole `Telescope`: the
mount link (with its capabilities), the motion primitives, the clock, safety, the
supervisor's phase reporting, the tracking-error history and the event sink, and
the few settings a procedure reads. `Telescope` implements it; nothing here imports
it, so the procedures and the telescope no longer import each other.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:
    from virtualstar.astro import EarthOrientation, MountLimits

    from .clock import Margins, MountClock
    from .feeder import FeederConfig
    from .link_interface import MountBackend
    from .motion import Motion
    from .on_target import OnTarget
    from .operations import Operation, Phase
    from .safety import Safety
    from .steering import Steering
    from .tracking_errors import TrackingErrorHistory
    from .trajectories import Points

__all__ = ["PhaseSink", "Station"]


class PhaseSink(Protocol):
    """How a procedure tells the clients where it is (the supervisor implements it)."""

    def phase(self, op: Operation, phase: Phase, **info: Any) -> None: ...

    def begun(self, op: Operation) -> None: ...


class Station(Protocol):
    """The server as a procedure sees it."""

    config: Any  # TelescopeConfig: site, margins, tolerances (read only)
    link: MountBackend
    motion: Motion
    clock: MountClock
    margins: Margins  # leads and holds sized for the clock (clock.Margins)
    safety: Safety
    supervisor: PhaseSink
    errors: TrackingErrorHistory
    on_target: OnTarget  # the target's truth against the boresight
    steering: Steering  # the running track's offsets and corrections
    eop: EarthOrientation
    limits: MountLimits
    model: Any  # the pointing model, or None
    model_source: str
    track_rate_limit_deg_s: float
    emit: Callable[[str, dict[str, Any]], None]

    def feeder_config(self) -> FeederConfig: ...

    def log_event(self, level: str, kind: str, message: str, **fields: Any) -> None: ...

    def note_points(self, p: Points) -> None: ...

    def check_can_move(self) -> None:
        """Refuse a moving command on a passive server or without a mount."""
        ...
