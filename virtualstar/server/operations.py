"""Operations as a state machine: the phases, the transitions allowed, and when to resume.

An `Operation` is one client intent (slew to Vega, track a pass, park). It lives
from the command that creates it to a terminal phase; its futures `begun` and
`done` are resolved exactly once, whatever ends it (the supervisor makes sure).
An operation may run its procedure several times: after an interruption (a lost
mount connection, a buffer underrun) the target is re-acquired from where the
mount is, and clients waiting for the operation keep waiting for the same one.

Rules of the table below:

* every non-terminal phase may end in FAILED or ABORTED, or be INTERRUPTED; an
  interrupted operation starts again at PREPARING;
* SLEWING may be entered again from WAITING/JOINING: a join planned too late for
  the host is planned again from where the mount is (a paced mount does not wait);
* a move at rates (a hand pad) is SLEWING until its run-out: SLEWING → ENDING;
* DONE is reached only from SETTLING (a hold verified at its target), MEASURING
  or ENDING (a track brought to rest);
* terminal phases have no way out.

`resume_decision` is the one place that decides whether an interrupted operation
starts again.
"""

from __future__ import annotations

import asyncio
import contextvars
import enum
from dataclasses import dataclass, field
from typing import Any

from .exceptions import MountUnavailable, TrackingLost, VssError

__all__ = ["TERMINAL", "TRANSITIONS", "IllegalTransition", "Operation", "Phase", "Resume",
           "current_operation", "resume_decision"]

#: The id of the operation whose task is running (None outside operations): set by the
#: supervisor for an operation's task, inherited by every task it starts (its feeder), and
#: written beside each command the mount link sends, so the log says who moved the mount.
current_operation: contextvars.ContextVar[int | None] = contextvars.ContextVar(
    "current_operation", default=None)

MAX_RESUMES = 10  # re-acquisitions of one operation before it gives up


class Phase(enum.IntEnum):
    """Where an operation is; `label` is the name clients see."""

    STARTING = 0  # accepted, waiting for the previous operation to end
    PREPARING = 1  # fault check, the mount brought to rest, axes powered
    PLANNED = 2  # a satellite pass chosen and precomputed ("pass planned")
    SLEWING = 3  # point-to-point move (to a fixed place, or the rest point of a run-up)
    WAITING = 4  # holding until the run-up begins (a pass that has not risen yet)
    JOINING = 5  # the run-up: accelerating onto the trajectory
    SETTLING = 6  # on the target; arrival verified at the end of the settle time
    TRACKING = 7
    MEASURING = 8  # pointing sample: the guide camera measures
    INTERRUPTED = 9  # the mount or the trajectory was lost; re-acquiring
    ENDING = 10  # the track ended; bringing the mount to rest
    DONE = 11
    FAILED = 12
    ABORTED = 13

    @property
    def label(self) -> str:
        return _LABELS.get(self, self.name.lower())


_LABELS = {Phase.PLANNED: "pass planned"}

TERMINAL = frozenset({Phase.DONE, Phase.FAILED, Phase.ABORTED})
_END = frozenset({Phase.FAILED, Phase.ABORTED, Phase.INTERRUPTED})

TRANSITIONS: dict[Phase, frozenset[Phase]] = {
    Phase.STARTING: frozenset({Phase.PREPARING}) | _END,
    Phase.PREPARING: frozenset({Phase.PLANNED, Phase.SLEWING, Phase.WAITING}) | _END,
    Phase.PLANNED: frozenset({Phase.SLEWING, Phase.WAITING}) | _END,
    Phase.SLEWING: frozenset({Phase.SLEWING, Phase.WAITING, Phase.JOINING, Phase.SETTLING,
                              Phase.MEASURING, Phase.ENDING}) | _END,
    Phase.WAITING: frozenset({Phase.SLEWING, Phase.JOINING}) | _END,
    Phase.JOINING: frozenset({Phase.SLEWING, Phase.SETTLING, Phase.TRACKING}) | _END,
    Phase.SETTLING: frozenset({Phase.TRACKING, Phase.ENDING, Phase.DONE}) | _END,
    Phase.TRACKING: frozenset({Phase.ENDING}) | _END,
    Phase.MEASURING: frozenset({Phase.DONE}) | _END,
    Phase.INTERRUPTED: frozenset({Phase.PREPARING, Phase.FAILED, Phase.ABORTED}),
    Phase.ENDING: frozenset({Phase.DONE}) | _END,
    Phase.DONE: frozenset(),
    Phase.FAILED: frozenset(),
    Phase.ABORTED: frozenset(),
}


class IllegalTransition(RuntimeError):
    """A procedure asked for a phase change the table does not allow (a bug)."""


class Resume(enum.Enum):
    NO = "no"  # the operation ends with the error
    NOW = "now"  # re-acquire the target from where the mount is, at once
    WHEN_CONNECTED = "when connected"  # wait for the mount to come back, then re-acquire


def resume_decision(error: VssError, *, resumable: bool, resumes: int,
                    max_resumes: int = MAX_RESUMES) -> Resume:
    """Decide whether an operation interrupted by `error` starts again.

    Only tracking operations resume (a slew or a park that lost the mount is simply
    reported); a fault, a refusal or a bad target never resumes; a lost connection
    waits for the mount; a trajectory the mount stopped following (underrun) is
    re-acquired at once. After `max_resumes` the operation gives up.
    """
    if not resumable or resumes >= max_resumes:
        return Resume.NO
    if isinstance(error, MountUnavailable):
        return Resume.WHEN_CONNECTED
    if isinstance(error, TrackingLost):
        return Resume.NOW
    return Resume.NO


@dataclass(eq=False)
class Operation:
    """One operation: id, kind, target, phase, info, and its two answers.

    begun: resolved when the operation has reached what its request waits for
    (landed and tracking, a pass planned, ...) or has ended; done: when it ended.
    """

    id: int
    kind: str
    target: str
    resumable: bool = False
    phase: Phase = Phase.STARTING
    info: dict[str, Any] = field(default_factory=dict)
    begun: asyncio.Future | None = None
    done: asyncio.Future | None = None
    task: asyncio.Task | None = None
    attempt: asyncio.Task | None = None
    resumes: int = 0
    end_reason: VssError | None = None  # why the supervisor ended it (stop, replace, shutdown)
    interruption: VssError | None = None  # why its procedure was cut (fault, lost mount)

    def advance(self, phase: Phase, **info: Any) -> None:
        """Move to `phase` (checked against TRANSITIONS) and merge `info`."""
        if phase is not self.phase and phase not in TRANSITIONS[self.phase]:
            raise IllegalTransition(f"operation {self.id} ({self.kind}): {self.phase.label} -> "
                                    f"{phase.label} is not a transition of the table")
        self.phase = phase
        self.info.update(info)

    @property
    def finished(self) -> bool:
        return self.phase in TERMINAL

    def as_dict(self) -> dict[str, Any]:
        return {"id": self.id, "kind": self.kind, "target": self.target,
                "phase": self.phase.label, "info": self.info}
