"""Plan a night: satellite passes as fixed blocks, sidereal targets in the gaps by priority.

1. Each satellite target's passes (trimmed to the part that meets its constraints) become
   fixed blocks, as many as its `repeats`, highest priority first; a pass that would
   overlap a block already placed (slew time included) is left out, saying whose it is.
2. The sidereal targets, highest priority first (ties in file order), each get the
   earliest start at which the whole block — one grid step of margin either side — meets
   its constraints, a repeat is at least `cadence_s` after the one before, and the slew
   from the block before and to the block after fits in between (`gap_s`: the mount's
   point-to-point slew with its rate and acceleration limits, plus `setup_s` for the
   VSS to acquire and settle).

Slews follow the cable wrap: each block's path (its start azimuth and the signed azimuth
it travels) is placed on the turn of the wrap the mount reaches from the block before,
as the VSS does (`unwrap_azimuth`), starting from the park position; a slew is the
mount's move between those turns, which may be the long way round. A placement is
accepted only when every slew of the whole chain still fits.

Deterministic: no randomness, ties broken by file order. Every target left out is listed
with the reason: the constraint that never holds, or the blocks that took its time.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from functools import cached_property
from typing import Any

import numpy as np

from virtualstar.astro import MountLimits, UnreachablePath, iso_utc

from .exceptions import PlanFileError
from .sky import NightGrid, TargetSky, _runs, plan_slew_deg, slew_s

__all__ = ["PARK_AZ_DEG", "PARK_EL_DEG", "SETUP_S", "Block", "Plan", "mount_chain", "schedule"]

PARK_AZ_DEG, PARK_EL_DEG = 0.0, 85.0  # the VSS's default park position (mapping.py)

SETUP_S = 15.0  # mount seconds the VSS needs besides the slew: run-up, lead, settle, margins
EMULATOR_LIMITS = MountLimits(az_max_rate_deg_s=6.0, el_max_rate_deg_s=6.0,
                              az_max_accel_deg_s2=3.0, el_max_accel_deg_s2=3.0)


@dataclass(frozen=True)
class Block:
    """One scheduled block: a target from start to end (µs), where it is at both ends (deg)."""

    target: str
    kind: str  # star, radec or satellite
    repeat: int  # 1-based
    priority: float
    start_us: int
    end_us: int
    start_az_deg: float
    start_el_deg: float
    end_az_deg: float
    end_el_deg: float
    slew_s: float = 0.0  # from the block before (or from the plan's start place)
    az_travel_deg: float = 0.0  # signed azimuth the target moves during the block
    constraints: dict[str, float] = field(default_factory=dict)  # values at the start

    @property
    def duration_s(self) -> float:
        return (self.end_us - self.start_us) / 1e6

    def as_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["start_utc"] = iso_utc(self.start_us)
        d["end_utc"] = iso_utc(self.end_us)
        d["duration_s"] = self.duration_s
        return d


@dataclass
class Plan:
    """A night's plan: blocks in time order and the targets left out with the reason."""

    program: str
    start_us: int
    end_us: int
    blocks: list[Block]
    left_out: list[dict[str, str]]
    site: dict[str, Any] = field(default_factory=dict)
    setup_s: float = SETUP_S
    program_spec: dict[str, Any] = field(default_factory=dict)  # the program, for re-planning

    @property
    def weighted_hours(self) -> float:
        """Sum of priority × hours over the blocks (the figure a scheduler maximises)."""
        return sum(b.priority * b.duration_s / 3600.0 for b in self.blocks)

    def as_dict(self) -> dict[str, Any]:
        return {"program": self.program, "start_utc": iso_utc(self.start_us),
                "end_utc": iso_utc(self.end_us), "start_us": self.start_us, "end_us": self.end_us,
                "site": self.site, "setup_s": self.setup_s,
                "priority_weighted_hours": self.weighted_hours,
                "blocks": [b.as_dict() for b in self.blocks], "left_out": self.left_out,
                "program_spec": self.program_spec}

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> Plan:
        """Read a plan back (vs plan --json); raise PlanFileError saying what is wrong.

        A plan comes from a file or a client: every value is checked for its type and range
        here, before a runner or the mount sees it."""
        keys = set(Block.__dataclass_fields__)
        try:
            if not isinstance(doc, dict) or not isinstance(doc["blocks"], list):
                raise TypeError("a table with a list of blocks expected")
            blocks = [Block(**{k: v for k, v in b.items() if k in keys}) for b in doc["blocks"]]
            plan = cls(doc["program"], doc["start_us"], doc["end_us"], blocks,
                       doc.get("left_out", []), doc.get("site", {}),
                       doc.get("setup_s", SETUP_S), doc.get("program_spec", {}))
            _check_plan(plan)
            plan.start_us, plan.end_us = int(plan.start_us), int(plan.end_us)
            plan.setup_s = float(plan.setup_s)
            return plan
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise PlanFileError(f"not a plan written by vs plan: {type(exc).__name__} {exc} "
                                "(expected program, start_us, end_us and blocks with target, "
                                "start_us, end_us, az/el)") from None


# mount times in a plan: integer µs since 1970, before 2**62 µs (year ~148 000), so that
# sums and differences of them stay within int64 wherever they go
_MAX_US = 2**62


def _check_us(name: str, value: Any) -> None:
    if (isinstance(value, bool) or not isinstance(value, (int, np.integer))
            or not 0 <= value < _MAX_US):
        raise ValueError(f"{name} = {str(value)[:40]!r}: expected mount time in integer µs "
                         f"since 1970, 0..2**62")


def _check_number(name: str, value: Any, lo: float, hi: float) -> None:
    if (isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating))
            or not lo <= value <= hi):  # NaN fails both comparisons
        raise ValueError(f"{name} = {str(value)[:40]!r}: expected a number in {lo:g}..{hi:g}")


def _check_plan(plan: Plan) -> None:
    """Refuse (ValueError/TypeError) a plan whose values could not come from `vs plan`."""
    for name, value, kind in (("program", plan.program, str), ("left_out", plan.left_out, list),
                              ("site", plan.site, dict), ("program_spec", plan.program_spec,
                                                          dict)):
        if not isinstance(value, kind):
            raise TypeError(f"{name}: a {kind.__name__} expected")
    _check_us("start_us", plan.start_us)
    _check_us("end_us", plan.end_us)
    if plan.end_us < plan.start_us:
        raise ValueError("end_us before start_us")
    _check_number("setup_s", plan.setup_s, 0.0, 86_400.0)
    for i, b in enumerate(plan.blocks):
        where = f"block {i + 1}"
        if not isinstance(b.target, str) or not isinstance(b.kind, str):
            raise TypeError(f"{where}: target and kind must be text")
        _check_us(f"{where} start_us", b.start_us)
        _check_us(f"{where} end_us", b.end_us)
        if b.end_us <= b.start_us:
            raise ValueError(f"{where}: end_us not after start_us")
        _check_number(f"{where} repeat", b.repeat, 1, 1e6)
        _check_number(f"{where} priority", b.priority, -1e6, 1e6)
        for name in ("start_az_deg", "end_az_deg", "az_travel_deg"):
            _check_number(f"{where} {name}", getattr(b, name), -3600.0, 3600.0)
        for name in ("start_el_deg", "end_el_deg"):
            _check_number(f"{where} {name}", getattr(b, name), -90.0, 90.0)
        _check_number(f"{where} slew_s", b.slew_s, 0.0, 86_400.0)
        if not isinstance(b.constraints, dict):
            raise TypeError(f"{where}: constraints: a table expected")


def schedule(program: str, grid: NightGrid, skies: list[TargetSky], passes: dict[str, list],
             satellites: list, *, limits: MountLimits = EMULATOR_LIMITS,
             setup_s: float = SETUP_S,
             start_place_deg: tuple[float, float] = (PARK_AZ_DEG, PARK_EL_DEG)) -> Plan:
    """Return the plan of a night (see the module docstring).

    skies: the sidereal targets observed on the grid; satellites: the satellite targets;
    passes: {satellite target name: its trimmed pass windows (sky.satellite_windows)}.
    """
    blocks: list[Block] = []
    left_out: list[dict[str, str]] = []
    ctx = _Context(limits, setup_s, start_place_deg, int(grid.t_us[0]))
    for target in sorted(satellites, key=lambda t: (-t.priority, t.index)):
        placed = 0
        reasons = []
        for w in passes.get(target.name, []):
            if placed >= target.repeats:
                break
            if (w["end_us"] - w["start_us"]) / 1e6 < 30.0:
                reasons.append(f"the pass at {iso_utc(w['start_us'])} meets its constraints for "
                               "less than 30 s")
                continue
            block = Block(target.name, "satellite", placed + 1, target.priority, w["start_us"],
                          w["end_us"], w["start_az_deg"], w["start_el_deg"], w["end_az_deg"],
                          w["end_el_deg"], az_travel_deg=w["az_travel_deg"],
                          constraints={"culmination_el_deg": round(w["culmination_el_deg"], 3),
                                       **({"meridian_cut": True} if w.get("meridian_cut") else {})})
            clash = _clash(blocks, block, ctx)
            if clash is not None:
                reasons.append(f"the pass at {iso_utc(w['start_us'])} overlaps {clash}")
                continue
            blocks.append(block)
            placed += 1
        if placed == 0:
            left_out.append({"target": target.name, "reason": "; ".join(reasons) or
                             "no pass meets its constraints in the night"})
        elif placed < target.repeats:
            left_out.append({"target": target.name, "reason": f"only {placed} of "
                             f"{target.repeats} passes fit: " + ("; ".join(reasons) if reasons
                             else "no other pass meets its constraints in the night")})
    for sky in sorted(skies, key=lambda s: (-s.target.priority, s.target.index)):
        _place_sidereal(sky, grid, blocks, left_out, ctx)
    blocks.sort(key=lambda b: b.start_us)
    blocks = _with_slews(blocks, ctx)
    return Plan(program, int(grid.t_us[0]), int(grid.t_us[-1]), blocks, left_out,
                setup_s=setup_s)


def _place_sidereal(sky: TargetSky, grid: NightGrid, blocks: list[Block], left_out: list,
                    ctx: _Context) -> None:
    target = sky.target
    valid = sky.valid
    steps = int(math.ceil(target.duration_s / grid.step_s))
    if sky.az_deg is None or sky.el_deg is None:  # valid nowhere: nothing to place
        left_out.append({"target": target.name,
                         "reason": _why_not(sky, grid, np.zeros(len(valid), bool), blocks,
                                            steps, 0)})
        return
    # ok[i]: a block starting at grid index i has every grid point from i-1 to i+steps+1 valid
    n = len(valid)
    padded = np.r_[False, valid, False]
    run = np.convolve(padded.astype(np.int64), np.ones(steps + 3, np.int64), "valid")
    ok = np.zeros(n, bool)
    ok[: len(run)] = run == steps + 3  # run[i] sums the window [i-1, i+steps+1]
    az_path = np.unwrap(np.radians(sky.az_deg))
    placed = 0
    last_start: int | None = None
    reasons: list[str] = []
    duration_us = int(round(target.duration_s * 1e6))
    for _ in range(target.repeats):
        found = None
        for i in _free_starts(np.flatnonzero(ok), grid, duration_us, blocks, ctx.setup_s):
            start = int(grid.t_us[i])
            if last_start is not None and start < last_start + int(target.cadence_s * 1e6):
                continue
            if i + steps >= n:
                break
            end = start + int(round(target.duration_s * 1e6))
            j = min(int(i + steps), n - 1)
            block = Block(target.name, target.kind, placed + 1, target.priority, start, end,
                          float(sky.az_deg[i]), float(sky.el_deg[i]), float(sky.az_deg[j]),
                          float(sky.el_deg[j]),
                          az_travel_deg=float(np.degrees(az_path[j] - az_path[i])),
                          constraints={"el_deg": round(float(sky.el_deg[i]), 3),
                                       "sun_el_deg": round(float(grid.sun_el_deg[i]), 3)})
            if _clash(blocks, block, ctx, explain=False) is None:
                found = block
                break
        if found is None:
            reasons.append(_why_not(sky, grid, ok, blocks, steps, placed))
            break
        blocks.append(found)
        blocks.sort(key=lambda b: b.start_us)
        placed += 1
        last_start = found.start_us
    if placed < target.repeats:
        left_out.append({"target": target.name, "reason": (
            reasons[0] if placed == 0 else f"only {placed} of {target.repeats} repeats fit: "
            f"{reasons[0]}")})


@dataclass(frozen=True)
class _Context:
    limits: MountLimits
    setup_s: float
    start_place_deg: tuple[float, float]
    start_us: int

    @cached_property
    def max_gap_us(self) -> int:
        """The longest slew + setup there can be: a whole wrap in azimuth, 90° in elevation."""
        lim = self.limits
        worst = plan_slew_deg(lim.wrap_min_deg, 0.0, lim.wrap_max_deg, 90.0, lim)
        return int((worst + self.setup_s) * 1e6) + 1


def _free_starts(candidates: np.ndarray, grid: NightGrid, duration_us: int, blocks: list[Block],
                 setup_s: float) -> np.ndarray:
    """Drop the candidate starts whose block would overlap a placed one (setup included)."""
    starts = grid.t_us[candidates]
    ends = starts + duration_us
    free = np.ones(candidates.shape, bool)
    margin = int(setup_s * 1e6)
    for b in blocks:
        free &= (ends + margin <= b.start_us) | (starts >= b.end_us + margin)
    return candidates[free]


def _clash(blocks: list[Block], new: Block, ctx: _Context, *, explain: bool = True
           ) -> str | None:
    """Return what `new` would collide with (slews and the cable wrap included), or None.

    explain=False returns "clash" instead of the description (the scheduler tries
    thousands of starts and only keeps the first that fits).
    """
    # first the neighbours with the shortest-way slew (a lower bound, cheap), then the chain
    reach_us = ctx.max_gap_us
    for b in blocks:
        if b.end_us + reach_us <= new.start_us or b.start_us >= new.end_us + reach_us:
            continue  # farther than any slew: cannot collide
        if not explain and b.start_us < new.end_us and new.start_us < b.end_us:
            return "clash"
        if b.end_us <= new.start_us:
            gap = slew_s(b.end_az_deg, b.end_el_deg, new.start_az_deg, new.start_el_deg,
                         ctx.limits) + ctx.setup_s
            if new.start_us - b.end_us < gap * 1e6:
                return f"{b.target} (until {iso_utc(b.end_us)}, then {gap:.0f} s to get here)"
        elif b.start_us >= new.end_us:
            gap = slew_s(new.end_az_deg, new.end_el_deg, b.start_az_deg, b.start_el_deg,
                         ctx.limits) + ctx.setup_s
            if b.start_us - new.end_us < gap * 1e6:
                return f"{b.target} (from {iso_utc(b.start_us)}, {gap:.0f} s away)"
        else:
            return f"{b.target} ({iso_utc(b.start_us)}..{iso_utc(b.end_us)})"
    chain = sorted([*blocks, new], key=lambda b: b.start_us)
    try:
        moves = mount_chain(chain, ctx.limits, ctx.start_place_deg)
    except UnreachablePath:
        return "the cable wrap (its azimuth path does not fit)" if explain else "clash"
    free_from = ctx.start_us
    for k, (b, (slew, _, _)) in enumerate(zip(chain, moves, strict=True)):
        if b.start_us - free_from < (slew + ctx.setup_s) * 1e6:
            if k == 0:
                return (f"the start of the plan ({slew + ctx.setup_s:.0f} s to get there from "
                        f"the mount's place)")
            return (f"the cable wrap (a {slew:.0f} s slew the long way round before "
                    f"{b.target} at {iso_utc(b.start_us)})")
        free_from = b.end_us
    return None


def mount_chain(blocks: list[Block], limits: MountLimits,
                start_place_deg: tuple[float, float] = (PARK_AZ_DEG, PARK_EL_DEG),
                ) -> list[tuple[float, float, float]]:
    """Return (slew_s, start mount az, end mount az) per block, in the blocks' order.

    Each block's azimuth path is put on the turn of the cable wrap nearest the mount's
    azimuth after the block before (what the VSS does); the slew is the real move
    between the two mount azimuths, the long way round when the wrap forces it.
    """
    here_az, here_el = start_place_deg
    out = []
    for b in blocks:
        start = _turn_deg(b.start_az_deg, b.az_travel_deg, here_az, limits)
        slew = plan_slew_deg(here_az, here_el, start, b.start_el_deg, limits)
        out.append((slew, start, start + b.az_travel_deg))
        here_az, here_el = start + b.az_travel_deg, b.end_el_deg
    return out


def _turn_deg(az_deg: float, travel_deg: float, anchor_deg: float, limits: MountLimits) -> float:
    """Return the mount azimuth at which a path of `travel_deg` from sky azimuth `az_deg`
    starts: unwrap_azimuth's rule (the turn of the wrap that holds the whole path, nearest
    the anchor) for a path given by its ends, in scalars (called for every candidate)."""
    lo, hi = min(az_deg, az_deg + travel_deg), max(az_deg, az_deg + travel_deg)
    k_min = math.ceil((limits.wrap_min_deg - lo) / 360.0)
    k_max = math.floor((limits.wrap_max_deg - hi) / 360.0)
    if k_min > k_max:
        raise UnreachablePath(f"the azimuth path spans {hi - lo:.1f} deg, more than fits in the "
                              f"cable wrap {limits.wrap_min_deg:g}..{limits.wrap_max_deg:g} deg")
    k = min(range(k_min, k_max + 1), key=lambda k: (abs(az_deg + 360.0 * k - anchor_deg), k))
    return az_deg + 360.0 * k


def _with_slews(blocks: list[Block], ctx: _Context) -> list[Block]:
    moves = mount_chain(blocks, ctx.limits, ctx.start_place_deg)
    return [Block(**{**asdict(b), "slew_s": round(slew, 2)})
            for b, (slew, _, _) in zip(blocks, moves, strict=True)]


def _why_not(sky: TargetSky, grid: NightGrid, ok: np.ndarray, blocks: list[Block], steps: int,
             placed: int) -> str:
    names = {"elevation": f"above {sky.target.min_el_deg:g}° and the horizon profile",
             "azimuth": "inside its azimuth windows",
             "sun_altitude": f"with the Sun below {sky.target.sun_max_el_deg:g}°",
             "sun_zone": "out of the Sun's exclusion zone",
             "moon_separation": f"{sky.target.moon_min_sep_deg:g}° from the Moon",
             "window": "inside its time window"}
    never = [names[k] for k in sky.never]
    if never:
        return "never " + " nor ".join(never) + " during the night"
    if not ok.any():
        runs = _runs(sky.valid)
        longest = max(((b - a) * grid.step_s for a, b in runs), default=0.0)
        return (f"its constraints leave no stretch of {steps * grid.step_s / 60:.0f} min "
                f"(the longest is {longest / 60:.0f} min)")
    # the blocks that took its time: those within reach of a stretch where it could start
    reach = steps * grid.step_s * 1e6 + 300e6
    runs = _runs(ok)
    takers = sorted({b.target for b in blocks if b.target != sky.target.name and any(
        b.end_us > grid.t_us[a] - 300e6 and b.start_us < grid.t_us[z] + reach for a, z in runs)})
    stretches = ", ".join(f"{_hm(grid.t_us[a])}–{_hm(grid.t_us[b])}"
                          for a, b in runs[:4])
    return (f"no free time left where it can be observed ({stretches} UTC, starts): taken by "
            f"{', '.join(takers) or 'its own earlier repeats (cadence)'}")




def _hm(t_us) -> str:
    return iso_utc(int(t_us))[11:16]
