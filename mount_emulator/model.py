"""Hold the mount's arrays and offer the commands a controller firmware would.

`MountModel` owns the state, parameter and trajectory arrays, runs the compiled
`physics.step` for any number of ticks, and implements the commands (power,
slew, manual move, stop, trajectory init/start/reset/push, UTC sync, fault
reset) by checking the state-machine table and writing slots. It has no clock,
no socket and no asyncio: the ASTCom server (`emulator.MountEmulator`) and the
tests drive it. Every command is applied between two ticks.
"""

from __future__ import annotations

import math

import numpy as np

from mount_emulator import layout as L
from mount_emulator.exceptions import (
    CommandRejected,
    ReplaceRefused,
    TargetOutOfRange,
    TrajectoryError,
)
from mount_emulator.physics import initial_state, step
from mount_emulator.states import (
    STATUS_SYNC_ARMED,
    STATUS_TRAJ_STARTED,
    STATUS_UNDERRUN,
    AxisEvent,
    AxisState,
    allowed_events,
    next_state,
)

__all__ = ["DEFAULT_TRAJ_CAPACITY", "MountModel"]

DEFAULT_TRAJ_CAPACITY = 4096
_NO_TRACE_SRC = np.zeros(0, dtype=np.int64)
_NO_TRACE = np.zeros((0, 0))


class MountModel:
    """Two-axis mount: arrays, compiled step and commands.

    Angles in radians unless a name says ``_deg``; time in integer µs of mount time.
    """

    def __init__(
        self,
        *,
        start_us: int,
        params: np.ndarray | None = None,
        az_rad: float = 0.0,
        el_rad: float = math.radians(20.0),
        traj_capacity: int = DEFAULT_TRAJ_CAPACITY,
    ) -> None:
        self.params = L.default_params() if params is None else np.array(params, dtype=np.float64)
        self.state = initial_state(self.params, start_us=start_us, az_rad=az_rad, el_rad=el_rad)
        self.traj_t = np.zeros(traj_capacity, dtype=np.int64)
        self.traj_p = np.zeros((traj_capacity, 2))
        self.traj_v = np.full((traj_capacity, 2), np.nan)

    # ------------------------------------------------------------------ running
    def run(self, n_ticks: int, trace: np.ndarray | None = None,
            trace_src: np.ndarray | None = None, trace_dst: np.ndarray | None = None) -> int:
        """Advance ``n_ticks`` ticks; fill ``trace[:, trace_dst]`` from ``state[trace_src]``; return events."""
        if trace is None or trace_src is None or len(trace_src) == 0:
            return step(self.state, self.params, self.traj_t, self.traj_p, self.traj_v,
                        n_ticks, _NO_TRACE, _NO_TRACE_SRC, _NO_TRACE_SRC)
        return step(self.state, self.params, self.traj_t, self.traj_p, self.traj_v,
                    n_ticks, trace, trace_src, trace_dst)

    def record(self, n_ticks: int, names: list[str]) -> np.ndarray:
        """Advance ``n_ticks`` and return the per-tick values of the named state slots (n × k)."""
        src = np.array([L.STATE_INDEX[n] for n in names], dtype=np.int64)
        trace = np.zeros((n_ticks, len(names)))
        self.run(n_ticks, trace, src, np.arange(len(names), dtype=np.int64))
        return trace

    # ------------------------------------------------------------------ reading
    @property
    def mount_time_us(self) -> int:
        """Mount clock now, integer µs since 1970 UTC."""
        return int(self.state[L.G_MOUNT_US])

    @property
    def true_time_us(self) -> int:
        """True UTC of the current tick (the emulated GPS truth), µs since 1970."""
        return int(self.state[L.G_TRUE_US])

    def axis_slot(self, axis: int, field: int) -> float:
        """Return one per-axis state value (``layout.A_*``)."""
        return float(self.state[L.state_index(axis, field)])

    def axis_state(self, axis: int) -> AxisState:
        return AxisState(int(self.state[L.state_index(axis, L.A_STATE)]))

    @property
    def mount_state(self) -> AxisState:
        return AxisState(int(self.state[L.G_MOUNT_STATE]))

    def param(self, name: str) -> float:
        return float(self.params[L.PARAM_INDEX[name]])

    def set_param(self, name: str, value: float) -> None:
        """Set a parameter by its registered name; takes effect at the next tick."""
        self.params[L.PARAM_INDEX[name]] = float(value)

    # ----------------------------------------------------------------- commands
    def _event(self, axes: tuple[int, ...], event: AxisEvent, command: str) -> None:
        for a in axes:
            cur = int(self.state[L.state_index(a, L.A_STATE)])
            if next_state(cur, event) < 0:
                raise CommandRejected(command, f"{L.AXES[a]} {AxisState(cur).name}", allowed_events(cur))
        for a in axes:
            i = L.state_index(a, L.A_STATE)
            self.state[i] = next_state(int(self.state[i]), event)
        self._refresh_mount_state()

    def _refresh_mount_state(self) -> None:
        states = [int(self.state[L.state_index(a, L.A_STATE)]) for a in range(2)]
        if AxisState.FAULT in states:
            mstate = AxisState.FAULT
        else:
            order = (AxisState.TRACKING, AxisState.SLEWING, AxisState.MANUAL,
                     AxisState.STOPPING, AxisState.HOLDING)
            mstate = next((s for s in order if s in states), AxisState.OFF)
        self.state[L.G_MOUNT_STATE] = int(mstate)

    def power_on(self) -> None:
        """Close the loops on both axes, holding where they stand."""
        for a in range(2):
            if self.axis_state(a) == AxisState.OFF:
                enc = self.state[L.state_index(a, L.A_ENC)]
                self.state[L.state_index(a, L.A_REF)] = enc
                self.state[L.state_index(a, L.A_TARGET)] = enc
        self._event((0, 1), AxisEvent.POWER_ON, "power_on")

    def power_off(self) -> None:
        """Cut both drives and apply the brakes."""
        self._event((0, 1), AxisEvent.POWER_OFF, "power_off")

    def stop(self) -> None:
        """Ramp both axes to rest under the acceleration limit."""
        self._event((0, 1), AxisEvent.STOP, "stop")

    def _check_limits(self, axis: int, value_rad: float) -> None:
        lo = self.params[L.param_index(axis, L.P_POS_MIN)]
        hi = self.params[L.param_index(axis, L.P_POS_MAX)]
        if not (lo <= value_rad <= hi) or not math.isfinite(value_rad):
            raise TargetOutOfRange(L.AXES[axis], math.degrees(value_rad), math.degrees(lo), math.degrees(hi))

    def slew(self, az_rad: float, el_rad: float) -> None:
        """Move both axes point-to-point under their rate and acceleration limits."""
        self._check_limits(0, az_rad)
        self._check_limits(1, el_rad)
        self._event((0, 1), AxisEvent.SLEW, "slew")
        self.state[L.state_index(0, L.A_TARGET)] = az_rad
        self.state[L.state_index(1, L.A_TARGET)] = el_rad

    def move(self, axis: int, rate_rad_s: float) -> None:
        """Move one axis at a constant rate (ramped under the acceleration limit)."""
        vmax = self.params[L.param_index(axis, L.P_VMAX)]
        if not math.isfinite(rate_rad_s) or abs(rate_rad_s) > vmax:
            raise TargetOutOfRange(L.AXES[axis] + " rate", math.degrees(rate_rad_s),
                                   -math.degrees(vmax), math.degrees(vmax))
        self._event((axis,), AxisEvent.MOVE, "move")
        self.state[L.state_index(axis, L.A_MANUAL_RATE)] = rate_rad_s

    def safety_reset(self) -> None:
        """Clear latched faults; faulted axes go to OFF (a persisting cause trips again)."""
        self.state[L.G_FAULTS] = 0
        self.state[L.G_HB_LAST_TICK] = self.state[L.G_TICK]
        for a in range(2):
            self.state[L.state_index(a, L.A_FAULTS)] = 0
            i = L.state_index(a, L.A_STATE)
            if int(self.state[i]) == AxisState.FAULT:
                self.state[i] = next_state(AxisState.FAULT, AxisEvent.RESET)
        self._refresh_mount_state()

    def clear_injections(self) -> None:
        """End every fault injection: ``inject_*`` parameters to their defaults, grown
        degradations (friction, rattling, heat, clock drift) back to zero.

        Latched faults stay latched (`safety_reset` clears them); the winding temperature
        cools down by itself.
        """
        for slot in L.PARAM_SLOTS:
            if "inject_" in slot.name:
                self.params[slot.index] = slot.default
        self.state[L.G_DRIFT_INJ_PPM] = 0.0
        for a in range(2):
            for field in (L.A_FRIC_INJ, L.A_RES_AMP, L.A_RES_PHASE, L.A_HEAT_INJ):
                self.state[L.state_index(a, field)] = 0.0

    # --------------------------------------------------------------- trajectory
    @property
    def traj_capacity(self) -> int:
        return len(self.traj_t)

    def traj_count(self) -> int:
        return int(self.state[L.G_TRAJ_TAIL] - self.state[L.G_TRAJ_HEAD])

    def traj_free(self) -> int:
        """Return how many points fit (one slot is kept for the point before the segment)."""
        return self.traj_capacity - 1 - self.traj_count()

    def traj_init(self) -> None:
        """Empty the buffer and zero its counters; refused while tracking."""
        if AxisState.TRACKING in (self.axis_state(0), self.axis_state(1)):
            raise CommandRejected("traj.init", "TRACKING", ["traj.reset", "stop"])
        self._clear_buffer()
        for i in (L.G_TRAJ_LATE, L.G_TRAJ_ACCEPTED, L.G_TRAJ_UNDERRUNS, L.G_TRAJ_OUT_OF_RANGE,
                  L.G_TRAJ_REPLACES, L.G_TRAJ_REPLACE_REFUSED, L.G_TRAJ_DROPPED,
                  L.G_TRAJ_REPLACE_LEAD_US):
            self.state[i] = 0
        self.state[L.G_STATUS] = int(self.state[L.G_STATUS]) & ~(STATUS_UNDERRUN | STATUS_TRAJ_STARTED)

    def _clear_buffer(self) -> None:
        tail = self.state[L.G_TRAJ_TAIL]
        self.state[L.G_TRAJ_HEAD] = tail
        self.state[L.G_TRAJ_BASE] = tail
        self.state[L.G_TRAJ_LAST_US] = 0
        self.state[L.G_SEG_HEAD] = -1  # drop the cached Hermite segment

    def traj_start(self) -> None:
        """Start following the buffer on both axes (they must be holding)."""
        self._event((0, 1), AxisEvent.TRACK, "traj.start")
        self.state[L.G_STATUS] = (int(self.state[L.G_STATUS]) | STATUS_TRAJ_STARTED) & ~STATUS_UNDERRUN

    def traj_reset(self) -> None:
        """Abort the trajectory: tracking axes ramp to rest, the buffer empties."""
        for a in range(2):
            if self.axis_state(a) == AxisState.TRACKING:
                self._event((a,), AxisEvent.STOP, "traj.reset")
        self._clear_buffer()
        self.state[L.G_STATUS] = int(self.state[L.G_STATUS]) & ~STATUS_TRAJ_STARTED

    def traj_push(self, t_us, az_rad, el_rad, az_rate_rad_s=None, el_rate_rad_s=None) -> int:
        """Append time-tagged points; return how many were accepted.

        A point is rejected (and counted in ``traj.late``) when its time tag is
        not after both the mount time (plus ``traj.late_margin_us``) and the
        previous point; outside the axis limits it is counted in
        ``traj.out_of_range``. Points beyond the free space are neither stored
        nor counted: push them again later.
        """
        t, az, el, vaz, vel = _points(t_us, az_rad, el_rad, az_rate_rad_s, el_rate_rad_s)
        earliest = self.state[L.G_MOUNT_US] + self.params[L.Q_LATE_MARGIN_US]
        return self._append(t, az, el, vaz, vel, earliest)

    def traj_replace_from(self, from_us, t_us, az_rad, el_rad, az_rate_rad_s=None,
                          el_rate_rad_s=None) -> int:
        """Drop every buffered point at or after mount time `from_us`, append new ones.

        Both happen between two ticks, so the axes never see a buffer half replaced.
        Refused (ReplaceRefused, counted in ``traj.replace_refused``, the buffer
        untouched) when `from_us` is less than ``traj.replace_min_lead_us`` ahead of
        the mount clock, or when the new points are not all at or after `from_us`,
        strictly increasing, finite and inside the axis limits. Returns how many new
        points were stored (those beyond the free space are not: push them later).
        ``traj.replaces`` counts the calls applied, ``traj.dropped`` the points dropped.
        """
        try:
            from_us = int(from_us)
        except (TypeError, ValueError, OverflowError):
            raise TrajectoryError(f"from_us must be an integer mount time in µs, got {from_us!r}") from None
        t, az, el, vaz, vel = _points(t_us, az_rad, el_rad, az_rate_rad_s, el_rate_rad_s)
        now = int(self.state[L.G_MOUNT_US])
        lead_min = int(self.params[L.Q_REPLACE_MIN_LEAD_US])
        problem = ""
        if from_us < now + lead_min:
            problem = (f"from_us {from_us} is {(from_us - now) / 1000:.1f} ms ahead of the mount "
                       f"clock ({now}); at least traj.replace_min_lead_us = {lead_min / 1000:g} ms "
                       "is needed")
        elif len(t) and (t[0] < from_us or np.any(np.diff(t) <= 0)):
            problem = "the new points must be at or after from_us and strictly increasing in time"
        elif len(t) and not self._inside_limits(az, el, vaz, vel):
            problem = "some new points are outside the axis limits or not finite"
        if problem:
            self.state[L.G_TRAJ_REPLACE_REFUSED] += 1
            raise ReplaceRefused(problem)
        cap = self.traj_capacity
        head = int(self.state[L.G_TRAJ_HEAD])
        tail = int(self.state[L.G_TRAJ_TAIL])
        dropped = 0
        while tail > head and self.traj_t[(tail - 1) % cap] >= from_us:
            tail -= 1
            dropped += 1
        self.state[L.G_TRAJ_TAIL] = tail
        self.state[L.G_TRAJ_LAST_US] = int(self.traj_t[(tail - 1) % cap]) if tail > head else 0
        self.state[L.G_SEG_HEAD] = -1  # the cached segment may end on a dropped point
        self.state[L.G_TRAJ_DROPPED] += dropped
        self.state[L.G_TRAJ_REPLACES] += 1
        self.state[L.G_TRAJ_REPLACE_LEAD_US] = from_us - now
        return self._append(t, az, el, vaz, vel, from_us - 1)

    def _inside_limits(self, az, el, vaz, vel) -> bool:
        lims = [(self.params[L.param_index(a, L.P_POS_MIN)], self.params[L.param_index(a, L.P_POS_MAX)])
                for a in range(2)]
        return bool(np.all((az >= lims[0][0]) & (az <= lims[0][1]) & (el >= lims[1][0])
                           & (el <= lims[1][1])) and not np.any(np.isinf(vaz) | np.isinf(vel)))

    def _append(self, t, az, el, vaz, vel, earliest) -> int:
        """Store points after `earliest` (µs) and the newest buffered point; return the count."""
        cap = self.traj_capacity
        tail = int(self.state[L.G_TRAJ_TAIL])
        head = int(self.state[L.G_TRAJ_HEAD])
        last = int(self.state[L.G_TRAJ_LAST_US]) if tail > head else -(2**62)
        lims = [(self.params[L.param_index(a, L.P_POS_MIN)], self.params[L.param_index(a, L.P_POS_MAX)])
                for a in range(2)]
        if len(t) > 1 and bool(np.all(np.diff(t) > 0)):
            return self._append_increasing(t, az, el, vaz, vel, max(earliest, last), lims)
        accepted = late = out = 0
        for k in range(len(t)):
            if tail - head >= cap - 1:
                break
            if t[k] <= earliest or t[k] <= last:
                late += 1
                continue
            if (not (lims[0][0] <= az[k] <= lims[0][1] and lims[1][0] <= el[k] <= lims[1][1])
                    or math.isinf(vaz[k]) or math.isinf(vel[k])):
                out += 1
                continue
            i = tail % cap
            self.traj_t[i] = t[k]
            self.traj_p[i, 0] = az[k]
            self.traj_p[i, 1] = el[k]
            self.traj_v[i, 0] = vaz[k]
            self.traj_v[i, 1] = vel[k]
            tail += 1
            last = int(t[k])
            accepted += 1
        self.state[L.G_TRAJ_TAIL] = tail
        self.state[L.G_TRAJ_LAST_US] = last if tail > head else 0
        self.state[L.G_TRAJ_LATE] += late
        self.state[L.G_TRAJ_OUT_OF_RANGE] += out
        self.state[L.G_TRAJ_ACCEPTED] += accepted
        return accepted

    def _append_increasing(self, t, az, el, vaz, vel, after, lims) -> int:
        """`_append` for a batch already increasing in time: the same rules, as arrays."""
        cap = self.traj_capacity
        tail = int(self.state[L.G_TRAJ_TAIL])
        head = int(self.state[L.G_TRAJ_HEAD])
        late = t <= after
        inside = ((az >= lims[0][0]) & (az <= lims[0][1]) & (el >= lims[1][0])
                  & (el <= lims[1][1]) & ~np.isinf(vaz) & ~np.isinf(vel))
        take = np.flatnonzero(~late & inside)
        room = cap - 1 - (tail - head)
        stored = take[:max(room, 0)]
        # once full, the points after are neither stored nor counted (push them later)
        full = len(stored) >= room
        considered = (int(stored[-1]) + 1 if len(stored) else 0) if full else len(t)
        idx = (tail + np.arange(len(stored))) % cap
        self.traj_t[idx] = t[stored]
        self.traj_p[idx, 0] = az[stored]
        self.traj_p[idx, 1] = el[stored]
        self.traj_v[idx, 0] = vaz[stored]
        self.traj_v[idx, 1] = vel[stored]
        tail += len(stored)
        self.state[L.G_TRAJ_TAIL] = tail
        if len(stored):
            self.state[L.G_TRAJ_LAST_US] = int(t[stored[-1]])
        elif tail <= head:
            self.state[L.G_TRAJ_LAST_US] = 0
        self.state[L.G_TRAJ_LATE] += int(np.count_nonzero(late[:considered]))
        self.state[L.G_TRAJ_OUT_OF_RANGE] += int(np.count_nonzero(~late[:considered]
                                                                  & ~inside[:considered]))
        self.state[L.G_TRAJ_ACCEPTED] += len(stored)
        return len(stored)

    # --------------------------------------------------------------------- time
    def set_clock(self, start_us: int) -> None:
        """Put the true and the mount clock on `start_us` (µs since 1970 UTC; whole ticks).

        Only before the loop runs (a real-time emulator starting on host UTC): the
        PPS edges then fall on true whole seconds again.
        """
        start_us = int(start_us) // L.TICK_US * L.TICK_US
        self.state[L.G_TRUE_US] = float(start_us)
        self.state[L.G_MOUNT_US] = float(start_us)
        self.state[L.G_MOUNT_FRAC_US] = 0.0
        self.state[L.G_PPS_COUNTDOWN] = (1_000_000 - start_us % 1_000_000) // L.TICK_US

    def set_utc(self, utc_second: int) -> None:
        """Arm a UTC second (since 1970): the mount clock takes it at the next PPS edge."""
        self.state[L.G_PENDING_UTC_S] = int(utc_second)
        self.state[L.G_STATUS] = int(self.state[L.G_STATUS]) | STATUS_SYNC_ARMED


def _points(t_us, az_rad, el_rad, az_rate_rad_s, el_rate_rad_s) -> tuple[np.ndarray, ...]:
    """Check and flatten a batch of trajectory points (rates NaN when not given)."""
    try:
        t = np.asarray(t_us, dtype=np.int64).ravel()
        az = np.asarray(az_rad, dtype=np.float64).ravel()
        el = np.asarray(el_rad, dtype=np.float64).ravel()
    except (TypeError, ValueError, OverflowError) as exc:
        raise TrajectoryError(f"trajectory arrays must be numeric (t_us integer µs): {exc}") from None
    rates = az_rate_rad_s is not None or el_rate_rad_s is not None
    if rates and (az_rate_rad_s is None or el_rate_rad_s is None):
        raise TrajectoryError("give both az_rate_rad_s and el_rate_rad_s, or neither")
    if rates:
        try:
            vaz = np.asarray(az_rate_rad_s, dtype=np.float64).ravel()
            vel = np.asarray(el_rate_rad_s, dtype=np.float64).ravel()
        except (TypeError, ValueError) as exc:
            raise TrajectoryError(f"trajectory rates must be numeric: {exc}") from None
    else:
        vaz = vel = np.full(len(t), np.nan)
    if not (len(t) == len(az) == len(el) == len(vaz) == len(vel)):
        raise TrajectoryError(
            f"trajectory arrays differ in length: t_us {len(t)}, az {len(az)}, el {len(el)}"
            + (f", az_rate {len(vaz)}, el_rate {len(vel)}" if rates else ""))
    return t, az, el, vaz, vel
