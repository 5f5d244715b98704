"""The VSS commands: one parameter dataclass and one handler per command, in a table.

`COMMANDS[name] = Command(params_class, handler, doc, role=..., ends_program=...)`.
Parameters are checked against the dataclass fields before the handler runs, and
before a running program is ended: unknown keys and wrong types are refused with the
list of valid ones, every number must be finite and inside the range its field
declares (`within`), every text and list no longer than its field allows, and a
parameter class may check its fields together (`validate`). So a refused command
never reaches the supervisor and never ends what is running. Handlers are thin calls
into the `Telescope`. docs/vss-api.md lists the same table for client authors.

`role` says who may send a command (observers watch; operators also move and
configure) and `ends_program` whether a client's command ends a running program
first (everything that moves the mount or changes who drives it).
"""

from __future__ import annotations

import asyncio
import dataclasses
import math
import typing
import warnings
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import Any

from astcom_client.auth import Role
from virtualstar.astro.constants import SIDEREAL_RATE_ARCSEC_S
from virtualstar.files import FileRefused, read_text_file_async

from .exceptions import BadRequest, TargetUnreachable, UnknownCommand, VssError
from .offsets import OffsetLimits
from .operations import Phase
from .steering import MAX_OFFSET_ARCSEC, MAX_PATH_S, check_offset
from .targets import parse_target
from .telescope import Operation, Telescope

__all__ = ["COMMANDS", "Command", "Within", "dispatch", "within"]

LOOSEST_LIMITS = OffsetLimits(36_000.0, 36_000.0)  # the widest a server may be configured


@dataclass(frozen=True)
class Within:
    """The range a numeric parameter must lie in (inclusive unless `above`: then lo < x)."""

    lo: float
    hi: float
    unit: str = ""
    above: bool = False

    def check(self, cmd: str, name: str, value: float) -> None:
        low_ok = value > self.lo if self.above else value >= self.lo
        if not (low_ok and value <= self.hi):
            unit = f" ({self.unit})" if self.unit else ""
            if self.above and self.lo == 0:
                expected = f"a positive number, at most {self.hi:g}"
            else:
                expected = f"{'more than' if self.above else 'from'} {self.lo:g} to {self.hi:g}"
            raise BadRequest(f"{cmd}: {name}={_show(value)} is out of range: expected "
                             f"{expected}{unit}")


def within(lo: float, hi: float, unit: str = "", *, above: bool = False,
           default: Any = None) -> Any:
    """A dataclass field whose number must lie in lo..hi (see `Within`)."""
    return field(default=default, metadata={"within": Within(lo, hi, unit, above)})


def text(max_chars: int, *, default: Any = None) -> Any:
    """A dataclass field whose text holds at most `max_chars` characters."""
    return field(default=default, metadata={"max_chars": max_chars})


#: Defaults for fields that declare nothing: no text, list or map beyond these sizes, no
#: integer beyond int64, no float beyond ±1e9 (nothing the VSS takes is that large).
MAX_TEXT_CHARS = 1024
MAX_ITEMS = 10_000
INT64 = Within(-(2**63), 2**63 - 1)
ANY_FLOAT = Within(-1e9, 1e9)
MOUNT_TIME_US = Within(0, 2**63 - 1, "µs since 1970 UTC")
ONE_DAY_S = 86_400.0


@dataclass(frozen=True)
class NoParams:
    pass


@dataclass(frozen=True)
class TargetParams:
    radec: str | None = text(100)
    ra_deg: float | None = within(0.0, 360.0, "degrees")
    dec_deg: float | None = within(-90.0, 90.0, "degrees")
    star: str | None = text(100)
    altaz: str | None = text(100)
    az_deg: float | None = within(0.0, 360.0, "degrees")
    el_deg: float | None = within(-90.0, 90.0, "degrees")
    allow_sun: bool = False  # operators only: ignore the Sun/Moon zones for this operation
    answer_on_accept: bool = False  # answer once the checks passed and the operation began

    @property
    def target_fields(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(TargetParams)
                if f.name not in ("allow_sun", "answer_on_accept")}

    def validate(self) -> None:
        parse_target(self.target_fields)


@dataclass(frozen=True)
class TrackParams(TargetParams):
    tle: str | None = text(256 * 1024)
    sat: str | None = text(100)
    duration_s: float | None = within(0.0, ONE_DAY_S, "seconds", above=True)
    wait: bool = False
    max_wait_s: float | None = within(0.0, ONE_DAY_S, "seconds")
    closed_loop: bool = False  # guided by the guide camera (needs the server's --camera)

    def validate(self) -> None:
        if self.tle is None:
            if self.sat is not None:
                raise BadRequest("track: 'sat' selects a satellite inside 'tle'; no TLE was given")
            super().validate()
        elif any(getattr(self, k) is not None
                 for k in ("radec", "ra_deg", "star", "altaz", "az_deg")):
            raise BadRequest("track: give either a TLE or a sky target, not both")


@dataclass(frozen=True)
class SampleParams(TargetParams):
    settle_s: float = within(0.0, 600.0, "mount seconds", default=2.0)


@dataclass(frozen=True)
class MoveParams:
    # the mount's own rate limits are checked by the telescope; these bound absurd values
    az_rate_deg_s: float = within(-90.0, 90.0, "°/s", default=0.0)
    el_rate_deg_s: float = within(-90.0, 90.0, "°/s", default=0.0)
    allow_sun: bool = False


#: ASCOM's default guide rate: half the sidereal rate (arcseconds of sky per second).
DEFAULT_GUIDE_RATE_ARCSEC_S = 0.5 * SIDEREAL_RATE_ARCSEC_S


@dataclass(frozen=True)
class GuideParams:
    # the telescope checks the pulse against MAX_GUIDE_STEP_ARCSEC and MAX_GUIDE_RATE_ARCSEC_S
    # before anything moves (a guide pulse ends nothing); these only bound absurd values
    north_arcsec: float = within(-1e6, 1e6, "arcsec", default=0.0)
    east_arcsec: float = within(-1e6, 1e6, "arcsec", default=0.0)
    rate_arcsec_s: float = within(0.0, 1e6, "arcsec/s", above=True,
                                  default=DEFAULT_GUIDE_RATE_ARCSEC_S)


@dataclass(frozen=True)
class OffsetParams:
    # ra, dec, az, el, path, transverse (or all, with op=reset)
    axis: str = field(metadata={"max_chars": 16})
    op: str = text(8, default="add")  # add, set, rate, reset
    # arcsec (rate: arcsec/s; the server's offset limits apply on top: steering.py)
    arcsec: float | None = within(-MAX_OFFSET_ARCSEC, MAX_OFFSET_ARCSEC, "arcsec")
    # path only: seconds of time (rate: s/s)
    seconds: float | None = within(-MAX_PATH_S, MAX_PATH_S, "seconds")

    def validate(self) -> None:
        # names and combinations here; the rate against the server's own limits in steering
        check_offset(self.axis, self.op, self.arcsec, self.seconds, LOOSEST_LIMITS)


@dataclass(frozen=True)
class StopParams:
    reset_faults: bool = False


@dataclass(frozen=True)
class ParkParams:
    wait: bool = True


@dataclass(frozen=True)
class ModeParams:
    mode: str = text(16, default=dataclasses.MISSING)


@dataclass(frozen=True)
class ModelParams:
    path: str = text(4096, default=dataclasses.MISSING)


@dataclass(frozen=True)
class ErrorsParams:
    from_us: int | None = field(default=None, metadata={"within": MOUNT_TIME_US})
    to_us: int | None = field(default=None, metadata={"within": MOUNT_TIME_US})
    series: bool = False
    max_points: int = within(1, 100_000, "points", default=2000)


@dataclass(frozen=True)
class WaitParams:
    id: int | None = within(0, 2**63 - 1)


@dataclass(frozen=True)
class RunPlanParams:
    plan: dict  # as `vs plan --json` writes it
    done: list | None = None  # the records of a run this one resumes
    wait: bool = False


@dataclass(frozen=True)
class LogParams:
    since: int = within(0, 2**63 - 1, "the last seq seen", default=0)
    limit: int = within(1, 10_000, "events", default=1000)


@dataclass(frozen=True)
class Command:
    """One command: its parameters, its handler, who may send it, what it ends."""

    params: type
    handler: Callable[[Telescope, Any], Awaitable[Any]]
    doc: str
    role: Role = Role.OPERATOR  # the lowest role that may send it
    ends_program: bool = False  # a client's command ends a running program first
    # its answer waits for mount time to pass (an operation landing or ending, the mount at
    # rest, a program's end): `vs server --emulator --speed max` runs ahead only then
    awaits_mount_time: bool = False


def _check(cls: type, params: dict[str, Any], cmd: str) -> Any:
    """Return the parameters as `cls`, every one checked (see the module docstring)."""
    fields = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(params) - set(fields))
    if unknown:
        raise BadRequest(f"{cmd}: unknown parameters {_show(unknown)}; valid: "
                         f"{sorted(fields) or 'none'}")
    hints = typing.get_type_hints(cls)
    values = {}
    for name, f in fields.items():
        if name not in params:
            if f.default is dataclasses.MISSING:
                raise BadRequest(f"{cmd}: parameter {name!r} is required")
            continue
        values[name] = _value(cmd, name, params[name], hints[name], f.metadata)
    checked = cls(**values)
    validate = getattr(checked, "validate", None)
    if validate is not None:
        validate()
    return checked


def _value(cmd: str, name: str, value: Any, hint: Any, meta: Any) -> Any:
    allowed = typing.get_args(hint) or (hint,)
    if value is None and type(None) in allowed:
        return None
    if float in allowed and isinstance(value, int | float) and not isinstance(value, bool):
        if not math.isfinite(value):
            raise BadRequest(f"{cmd}: {name}={value!r} must be a finite number")
        # the parameter's own range first: Python compares an int with a float exactly, so
        # 10**400 is refused here (in the parameter's terms) before float() could overflow
        meta.get("within", ANY_FLOAT if int not in allowed else INT64).check(cmd, name, value)
        return float(value) if isinstance(value, int) and int not in allowed else value
    if not _plain_match(value, allowed):
        expected = " or ".join(t.__name__ for t in allowed if t is not type(None))
        raise BadRequest(f"{cmd}: {name}={_show(value)} has the wrong type; expected {expected}")
    if isinstance(value, int) and not isinstance(value, bool):
        meta.get("within", INT64).check(cmd, name, value)
    elif isinstance(value, str):
        top = meta.get("max_chars", MAX_TEXT_CHARS)
        if len(value) > top:
            raise BadRequest(f"{cmd}: {name} holds {len(value)} characters; at most {top}")
    elif isinstance(value, list | dict) and len(value) > MAX_ITEMS:
        raise BadRequest(f"{cmd}: {name} holds {len(value)} items; at most {MAX_ITEMS}")
    return value


def _show(value: Any) -> str:
    """A value for an error message, cut short (a client's 1 MB text is not echoed)."""
    text = repr(value) if not isinstance(value, float) else f"{value:g}"
    return text if len(text) <= 60 else text[:57] + "..."


class OperationFailed(VssError):
    """An operation a request waited for ended in failure; carries the failure's code
    (and `stopped` when a client's `stop` ended it)."""

    def __init__(self, message: str, code: str, *, stopped: bool = False) -> None:
        super().__init__(message)
        self.code = code
        self.stopped = stopped


def _plain_match(value: Any, allowed: tuple) -> bool:
    if isinstance(value, bool):
        return bool in allowed
    return any(kind in allowed and isinstance(value, kind) for kind in (int, str, dict, list))


async def _result(op: Operation, *, wait_done: bool, accepted: bool = False) -> dict[str, Any]:
    if accepted:  # the checks passed under the supervisor's lock: the operation is under way
        return op.as_dict()
    fut = op.done if wait_done else op.begun
    await asyncio.shield(fut)
    if op.phase in (Phase.FAILED, Phase.ABORTED):
        err = op.info.get("error", {})
        raise OperationFailed(err.get("message", "the operation failed"),
                              err.get("code", "internal"), stopped=bool(err.get("stopped")))
    return op.as_dict()


async def _ping(t: Telescope, p: NoParams) -> Any:
    return {"pong": True}


async def _status(t: Telescope, p: NoParams) -> Any:
    return await t.status()


async def _slew(t: Telescope, p: TargetParams) -> Any:
    target, name, fixed = parse_target(p.target_fields)
    if fixed is not None:
        op = await t.slew_altaz(*fixed, allow_sun=p.allow_sun)
    else:
        op = await t.follow_target(target, name, kind="slew", allow_sun=p.allow_sun)
    return await _result(op, wait_done=False, accepted=p.answer_on_accept)


async def _track(t: Telescope, p: TrackParams) -> Any:
    if p.tle is not None:
        sat = _satellite(p.tle, p.sat)
        op = await t.track_satellite(sat, max_wait_s=p.max_wait_s, allow_sun=p.allow_sun,
                                     closed_loop=p.closed_loop)
        return await _result(op, wait_done=p.wait, accepted=p.answer_on_accept)
    target, name, fixed = parse_target(p.target_fields)
    if fixed is not None:
        raise BadRequest("track: a fixed az/el does not move; use slew for it")
    op = await t.follow_target(target, name, kind="track", duration_s=p.duration_s,
                               allow_sun=p.allow_sun, closed_loop=p.closed_loop)
    return await _result(op, wait_done=p.wait, accepted=p.answer_on_accept)


def _satellite(tle: str, name: str | None):
    from catalogs import parse_tle_text
    from catalogs.exceptions import CatalogError
    from virtualstar.astro import Satellite
    from virtualstar.astro.exceptions import AstroError

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            records = parse_tle_text(tle, "the TLE text")
    except CatalogError as exc:
        raise BadRequest(str(exc)) from None
    if not records:
        raise BadRequest("the TLE text holds no satellite: expected a name line and two "
                         "element lines (1 ..., 2 ...)")
    if name is not None:
        key = name.strip().lower()
        chosen = [r for r in records if r.name.strip().lower() == key] or \
                 [r for r in records if key in r.name.strip().lower()]
        if not chosen:
            raise TargetUnreachable(f"no satellite named {name!r} in the TLE; it holds: "
                                    f"{', '.join(r.name.strip() for r in records[:20])}")
        record = chosen[0]
    else:
        record = records[0]
    try:
        return Satellite.from_record(record)
    except AstroError as exc:
        raise BadRequest(str(exc)) from None


async def _pointing_sample(t: Telescope, p: SampleParams) -> Any:
    target, name, fixed = parse_target(p.target_fields)
    if fixed is not None:
        from virtualstar.astro import FixedAltAz

        target = FixedAltAz(fixed[0] % 360.0, fixed[1])
    op = await t.pointing_sample(target, name, settle_s=p.settle_s, allow_sun=p.allow_sun)
    done = await _result(op, wait_done=True)
    return {"id": done["id"], **done["info"]["sample"]}


async def _move(t: Telescope, p: MoveParams) -> Any:
    op = await t.move(p.az_rate_deg_s, p.el_rate_deg_s, allow_sun=p.allow_sun)
    return await _result(op, wait_done=False)


async def _guide(t: Telescope, p: GuideParams) -> Any:
    return await t.guide(p.north_arcsec, p.east_arcsec, p.rate_arcsec_s)


async def _offset(t: Telescope, p: OffsetParams) -> Any:
    return await t.steering.offset(p.axis, p.op, arcsec=p.arcsec, seconds=p.seconds)


async def _stop(t: Telescope, p: StopParams) -> Any:
    return await t.stop(reset_faults=p.reset_faults)


async def _reset(t: Telescope, p: NoParams) -> Any:
    return await t.stop(reset_faults=True)


async def _park(t: Telescope, p: ParkParams) -> Any:
    op = await t.park()
    return await _result(op, wait_done=p.wait) if p.wait else op.as_dict()


async def _mode(t: Telescope, p: ModeParams) -> Any:
    return await t.set_mode(p.mode)


#: A pointing model is a few kilobytes; anything near this is not one.
MAX_MODEL_BYTES = 4 << 20


async def _load(t: Telescope, p: ModelParams) -> Any:
    try:  # off the event loop, and only a regular file: a FIFO would block every client
        text = await read_text_file_async(p.path, max_bytes=MAX_MODEL_BYTES,
                                          what="pointing model")
    except FileRefused as exc:
        raise BadRequest(f"cannot load {exc}") from None
    return t.load_model(p.path, text)


async def _unload(t: Telescope, p: NoParams) -> Any:
    return t.unload_model()


async def _errors(t: Telescope, p: ErrorsParams) -> Any:
    out: dict[str, Any] = {"stats": t.errors.stats(p.from_us, p.to_us).as_dict(),
                           "samples": t.errors.samples}
    if p.series:
        out["series"] = t.errors.series(p.from_us, p.to_us, p.max_points)
    return out


async def _wait(t: Telescope, p: WaitParams) -> Any:
    op = t.op
    if op is None or (p.id is not None and op.id != p.id):
        raise BadRequest(f"no running operation {p.id if p.id is not None else ''}".strip()
                         + (f"; the current one is {op.id}" if op else "; nothing is running"))
    return await _result(op, wait_done=True)


async def _run_plan(t: Telescope, p: RunPlanParams) -> Any:
    doc = await t.programs.start(p.plan, p.done, lambda cmd, params: execute(t, cmd, params))
    return await t.programs.wait() if p.wait else doc


async def _program(t: Telescope, p: NoParams) -> Any:
    return t.programs.status()


async def _log(t: Telescope, p: LogParams) -> Any:
    events = t.log.since(p.since)[: p.limit]
    return {"events": [e.as_dict() for e in events], "last_seq": t.log.last_seq,
            "dropped": dict(t.log.dropped)}


COMMANDS: dict[str, Command] = {
    "ping": Command(NoParams, _ping, "Answer at once (liveness).",
                    role=Role.NONE),
    "status": Command(NoParams, _status, "Positions, RA/Dec, states, errors, mount time.",
                      role=Role.OBSERVER),
    "slew": Command(TargetParams, _slew, "Slew to a target; sky targets are then tracked. "
                    "Answers when landed.",
                    ends_program=True, awaits_mount_time=True),
    "track": Command(TrackParams, _track, "Track a sky target or a satellite pass; answers "
                     "when tracking has begun (satellite: when the pass is planned), or at the "
                     "end with wait=true.",
                     ends_program=True, awaits_mount_time=True),
    "pointing_sample": Command(SampleParams, _pointing_sample, "Point at a target, hold, and "
                               "measure the star's offset with the guide camera (needs the "
                               "guide_measure role); answers with star, encoder, offset and "
                               "on-axis places.",
                               ends_program=True, awaits_mount_time=True),
    "move": Command(MoveParams, _move, "Turn the axes at az_rate_deg_s / el_rate_deg_s (a hand "
                    "pad) until stop, another command, or just before a limit or zone; answers "
                    "once moving.",
                    ends_program=True, awaits_mount_time=True),
    "guide": Command(GuideParams, _guide, "A guide pulse: offset the sky target being tracked "
                     "by north_arcsec / east_arcsec at rate_arcsec_s; answers with when the pulse "
                     "runs (mount µs) and the total offset."),
    "offset": Command(OffsetParams, _offset, "Offset the running track (PWI4-style): axis ra, "
                      "dec, az, el (arcsec), path (seconds of time, or arcsec along the track), "
                      "transverse (arcsec across it); op add, set, rate (per second) or reset; "
                      "applied gradually within the offset limits from 20 ms after acceptance "
                      "(replace_from); answers with from_us, reached_us, lead_ms and the "
                      "offsets."),
    "stop": Command(StopParams, _stop, "Stop the operation, bring the mount to rest; "
                    "reset_faults=true also clears latched faults.",
                    ends_program=True, awaits_mount_time=True),
    "reset_faults": Command(NoParams, _reset, "Stop and clear the mount's latched faults.",
                            ends_program=True, awaits_mount_time=True),
    "park": Command(ParkParams, _park, "Slew to the park position and power off.",
                    ends_program=True, awaits_mount_time=True),
    "set_mode": Command(ModeParams, _mode, "mode=active (commands move the mount) or passive "
                        "(watch only).",
                        ends_program=True),
    "load_model": Command(ModelParams, _load, "Load a pointing model: JSON or a TPOINT .mod "
                          "file (a regular file on the server, at most 4 MiB)."),
    "unload_model": Command(NoParams, _unload, "Drop the pointing model."),
    "errors": Command(ErrorsParams, _errors, "Tracking-error RMS and peak over a mount-time "
                      "window; series=true adds per-bin values.",
                      role=Role.OBSERVER),
    "wait": Command(WaitParams, _wait, "Wait until the running operation ends; return its summary.",
                    role=Role.OBSERVER, awaits_mount_time=True),
    "run_plan": Command(RunPlanParams, _run_plan, "Run a plan (vs plan's JSON) block by block, "
                        "re-planning after a missed, late or faulted block; answers when it "
                        "has begun, or at its end with wait=true.",
                        awaits_mount_time=True),
    "program": Command(NoParams, _program, "The program run: state, current block, the "
                       "blocks done with their tracking figures, re-plans, the plan.",
                       role=Role.OBSERVER),
    "log": Command(LogParams, _log, "The server's event log after seq `since` (at most "
                   "`limit`): operations and phases, faults, safety actions, commands with "
                   "their client and role, connections, failed logins; {events, last_seq, dropped}.",
                   role=Role.OBSERVER),
}



async def dispatch(telescope: Telescope, cmd: str, params: dict[str, Any], *,
                   ends_program: bool = True) -> Any:
    """Check parameters and run one command; raise VssError subclasses for the client.

    A client's command that moves the mount ends a running program first; the program's
    own commands (`execute`) do not.
    """
    command = COMMANDS.get(cmd)
    if command is None:
        raise UnknownCommand(f"unknown command {cmd!r}; valid commands: {', '.join(COMMANDS)}")
    checked = _check(command.params, params, cmd)
    if ends_program and command.ends_program and telescope.programs.running:
        await telescope.programs.cancel(f"ended by a client's {cmd}")
    if not command.awaits_mount_time:
        return await command.handler(telescope, checked)
    with telescope.clock.awaited():  # a client waits: lockstep time may run ahead meanwhile
        return await command.handler(telescope, checked)


async def execute(telescope: Telescope, cmd: str, params: dict[str, Any]) -> Any:
    """Run a command for the server's own program run (it does not end the program)."""
    return await dispatch(telescope, cmd, params, ends_program=False)
