"""Advance the whole mount by whole 100 µs ticks: the pure, compiled physics step.

`step(state, params, traj_t, traj_p, traj_v, n_ticks, trace, trace_src, trace_dst)`
is the only hot path. It reads and writes plain arrays (indices in `layout`),
never raises, never looks at a clock or a socket: status and faults are integers
in the state, and the return value is a bit set of the events seen (`states.EV_*`).

One tick, per axis, in this order:

1. clock: true time +100 µs; mount clock +100 µs × (1 + drift); on a 1 PPS edge
   (true time on a whole second) an armed UTC second replaces the mount clock;
2. sense: quantised absolute encoder on the axis (motor side), filtered velocity;
3. reference: hold, slew profile, manual ramp, stop ramp, or the trajectory
   buffer sampled by cubic Hermite interpolation at the mount time;
4. control: position PI → velocity PI(D) with velocity and acceleration
   feed-forward, velocity-command rate and acceleration limits, current limit,
   conditional-integration anti-windup;
5. watchdog: overcurrent, over-temperature, encoder fault, following error,
   axis limits, controller heartbeat, bus overvoltage — faults latch and cut the drive;
6. plant: current-loop lag, torque motor + cogging, motor and load inertias
   coupled by a spring-damper, viscous + Coulomb friction (implicit, so stiction
   is exact and stable at any step), gravity imbalance on elevation, holding
   brake when the drive is off; semi-implicit Euler at 100 µs (the 18–25 Hz
   resonance is sampled ≈ 400–550 times per period);
7. power: I²R winding heating with a thermal time constant, DC bus with supply
   resistance, regeneration into the bus capacitor, brake chopper.

Injected degradations (`inject_*` parameters, docs/mount-emulator.md "Fault injection")
enter at steps 1, 2 and 6: a growing clock drift, encoder glitches on pseudo-random ticks,
and on the plant a lost share of the torque constant, growing friction, a growing
rattling torque on the tube and growing winding heat. They cost one flag per axis per
block while none is set.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from mount_emulator.layout import (
    A_CUR,
    A_CUR_CMD,
    A_ENC,
    A_ENC_COUNTS,
    A_ERR,
    A_ERR_AS,
    A_ERR_PEAK_AS,
    A_FAULTS,
    A_FRIC_INJ,
    A_HEAT_INJ,
    A_INT_POS,
    A_INT_VEL,
    A_LOAD_ERR_AS,
    A_MANUAL_RATE,
    A_POS_DEG,
    A_POS_L,
    A_POS_M,
    A_POWER,
    A_PREV_ENC,
    A_PREV_EV,
    A_REF,
    A_REF_ACC,
    A_REF_VEL,
    A_RES_AMP,
    A_RES_PHASE,
    A_STATE,
    A_TARGET,
    A_TEMP,
    A_TORQUE,
    A_TWIST_AS,
    A_VEL_CMD,
    A_VEL_DEG_S,
    A_VEL_EST,
    A_VEL_L,
    A_VEL_M,
    ARCSEC,
    AXIS_STRIDE,
    G_BUS_V,
    G_CHOPPER_W,
    G_DRIFT_INJ_PPM,
    G_EVENTS,
    G_FAULTS,
    G_HB_LAST_TICK,
    G_MOUNT_FRAC_US,
    G_MOUNT_STATE,
    G_MOUNT_US,
    G_PENDING_UTC_S,
    G_PPS_COUNT,
    G_PPS_COUNTDOWN,
    G_PPS_ERR_US,
    G_REGEN_J,
    G_SEG_COEF,
    G_SEG_HEAD,
    G_SEG_SPAN_US,
    G_SEG_T0_US,
    G_SEG_TAIL,
    G_STATUS,
    G_SUPPLY_W,
    G_SYNC_COUNT,
    G_TICK,
    G_TRAJ_BASE,
    G_TRAJ_HEAD,
    G_TRAJ_REF_AZ,
    G_TRAJ_REF_EL,
    G_TRAJ_TAIL,
    G_TRAJ_UNDERRUNS,
    G_TRUE_US,
    P_AFF,
    P_AMAX,
    P_BRAKE,
    P_C,
    P_COG,
    P_COG_N,
    P_COULOMB,
    P_CTRL_AMAX,
    P_CTRL_VMAX,
    P_ENC_BITS,
    P_FERR_MAX,
    P_FRIC_FF,
    P_FRIC_VS,
    P_GRAV,
    P_I_MAX,
    P_I_TRIP,
    P_INJ_ENC,
    P_INJ_FRIC_GROWTH,
    P_INJ_GLITCH_COUNTS,
    P_INJ_GLITCH_RATE,
    P_INJ_HEAT_GROWTH,
    P_INJ_RES_GROWTH,
    P_INJ_RES_HZ,
    P_INJ_WINDING,
    P_INT_ZONE,
    P_J_FF,
    P_JL,
    P_JM,
    P_K,
    P_KI,
    P_KP,
    P_KT,
    P_KV,
    P_KVD,
    P_KVI,
    P_POS_MAX,
    P_POS_MIN,
    P_R_OHM,
    P_RTH,
    P_SETTLE_AS,
    P_T_MAX,
    P_TAU_I,
    P_TAU_TH,
    P_TAU_V,
    P_VFF,
    P_VISC,
    P_VMAX,
    PARAM_AXIS0,
    Q_AMBIENT_C,
    Q_BUS_C,
    Q_CHOPPER_ON_V,
    Q_CHOPPER_R,
    Q_DRIFT_PPM,
    Q_HB_TIMEOUT_S,
    Q_INJ_DRIFT_GROWTH,
    Q_INJECT_HB_MISS,
    Q_OVERVOLTAGE_V,
    Q_SUPPLY_R,
    Q_SUPPLY_V,
    STATE_AXIS0,
    STATE_SIZE,
    TICK_S,
    TICK_US,
)
from mount_emulator.states import (
    EV_ARRIVED,
    EV_FAULT,
    EV_PPS,
    EV_SYNC,
    EV_UNDERRUN,
    FAULT_ENCODER,
    FAULT_FOLLOWING,
    FAULT_HEARTBEAT,
    FAULT_LIMIT,
    FAULT_OVERCURRENT,
    FAULT_OVERTEMP,
    FAULT_OVERVOLTAGE,
    STATUS_CHOPPER,
    STATUS_FAULT,
    STATUS_SYNC_ARMED,
    STATUS_TIME_SYNCED,
    STATUS_UNDERRUN,
    TRANSITION_TABLE,
    AxisEvent,
    AxisState,
)

__all__ = ["initial_state", "step", "hermite_sample"]

# Compiled, cached, GIL released; fast-math without "nnan"/"ninf" (NaN marks missing rates)
_FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}
_jit = njit(cache=True, nogil=True, fastmath=_FASTMATH)
_inline = njit(cache=True, nogil=True, fastmath=_FASTMATH, inline="always")

# Plain ints for the compiled code (numba freezes module globals).
OFF = int(AxisState.OFF)
HOLDING = int(AxisState.HOLDING)
SLEWING = int(AxisState.SLEWING)
TRACKING = int(AxisState.TRACKING)
MANUAL = int(AxisState.MANUAL)
STOPPING = int(AxisState.STOPPING)
FAULT = int(AxisState.FAULT)
EVT_ARRIVED = int(AxisEvent.ARRIVED)
EVT_STOPPED = int(AxisEvent.STOPPED)
EVT_UNDERRUN = int(AxisEvent.UNDERRUN)
EVT_FAULT = int(AxisEvent.FAULT)

SAMPLE_OK = 0
SAMPLE_BEFORE = 1  # the mount time is before the first point: hold
SAMPLE_UNDERRUN = 2  # no point after the mount time
TWO_PI = 2.0 * math.pi
TICKS_PER_SECOND = 1_000_000 // TICK_US
# Per-block constants derived from the parameters (reciprocals, discretisation factors).
# Parameters only change between blocks, so computing them once per call is exact.
K_CPR = 0  # encoder counts per radian
K_RPC = 1  # radians per count
K_BETA_V = 2  # velocity-filter factor dt / (tau_v + dt)
K_ALPHA_I = 3  # current-lag factor dt / (tau_i + dt)
K_DT_JM = 4  # dt / J_motor
K_DT_JL = 5  # dt / J_load
K_INV_KT = 6
K_INV_VS = 7  # 1 / friction smoothing velocity
K_DT_TAU_TH = 8  # dt / thermal tau
K_KT_EFF = 9  # torque constant less an injected winding fault
K_GLITCH_P = 10  # probability of an injected encoder glitch per tick
K_DEGRADE = 11  # 1 while a gradual degradation is injected or has grown (see _degrade)
N_K = 12
PER_HOUR = 1.0 / 3600.0
RAD_TO_DEG = 180.0 / math.pi


@_inline
def _apply(state, sb, event):
    """Apply an event to the axis at state block ``sb``; return True if the state changed."""
    cur = int(state[sb + A_STATE])
    new = TRANSITION_TABLE[cur, event]
    if new >= 0 and new != cur:
        state[sb + A_STATE] = new
        return True
    return False


@_jit
def _tangent(traj_t, traj_p, traj_v, k, base, tail, ax):
    """Return the rate at point counter ``k``: given, else from its neighbours (rad/s)."""
    cap = traj_t.shape[0]
    i = k % cap
    m = traj_v[i, ax]
    if not math.isnan(m):
        return m
    has_prev = k - 1 >= base
    has_next = k + 1 < tail
    if has_prev and has_next:
        ip = (k - 1) % cap
        inx = (k + 1) % cap
        h0 = (traj_t[i] - traj_t[ip]) * 1e-6
        h1 = (traj_t[inx] - traj_t[i]) * 1e-6
        s0 = (traj_p[i, ax] - traj_p[ip, ax]) / h0
        s1 = (traj_p[inx, ax] - traj_p[i, ax]) / h1
        # derivative of the parabola through the three points (second-order accurate)
        return (s0 * h1 + s1 * h0) / (h0 + h1)
    if has_next:
        inx = (k + 1) % cap
        return (traj_p[inx, ax] - traj_p[i, ax]) / ((traj_t[inx] - traj_t[i]) * 1e-6)
    if has_prev:
        ip = (k - 1) % cap
        return (traj_p[i, ax] - traj_p[ip, ax]) / ((traj_t[i] - traj_t[ip]) * 1e-6)
    return 0.0


@_jit
def _segment_coefficients(traj_t, traj_p, traj_v, state, head, base, tail):
    """Cache the cubic Hermite polynomial of segment [head, head + 1] in the state."""
    cap = traj_t.shape[0]
    i0 = head % cap
    i1 = (head + 1) % cap
    span_us = float(traj_t[i1] - traj_t[i0])
    h = span_us * 1e-6
    for ax in range(2):
        p0 = traj_p[i0, ax]
        p1 = traj_p[i1, ax]
        m0 = _tangent(traj_t, traj_p, traj_v, head, base, tail, ax) * h
        m1 = _tangent(traj_t, traj_p, traj_v, head + 1, base, tail, ax) * h
        state[G_SEG_COEF + 4 * ax] = p0
        state[G_SEG_COEF + 4 * ax + 1] = m0
        state[G_SEG_COEF + 4 * ax + 2] = -3.0 * p0 - 2.0 * m0 + 3.0 * p1 - m1
        state[G_SEG_COEF + 4 * ax + 3] = 2.0 * p0 + m0 - 2.0 * p1 + m1
    state[G_SEG_T0_US] = float(traj_t[i0])
    state[G_SEG_SPAN_US] = span_us
    state[G_SEG_HEAD] = head
    state[G_SEG_TAIL] = tail


@_jit
def hermite_sample(traj_t, traj_p, traj_v, state, t_us, out):
    """Sample the trajectory at mount time ``t_us`` into ``out`` (pos[2], vel[2], acc[2]).

    Consumes points whose successor is already past. Returns SAMPLE_OK,
    SAMPLE_BEFORE (first point still in the future) or SAMPLE_UNDERRUN.
    Radians, rad/s, rad/s².
    """
    return _hermite_sample(traj_t, traj_p, traj_v, state, t_us, out)


@_inline
def _hermite_sample(traj_t, traj_p, traj_v, state, t_us, out):
    """`hermite_sample`, inlined into the tick loop (a call out of `_ticks` would bring
    back the reference counting that loop is compiled without)."""
    cap = traj_t.shape[0]
    head = int(state[G_TRAJ_HEAD])
    tail = int(state[G_TRAJ_TAIL])
    base = int(state[G_TRAJ_BASE])
    if tail - head < 1:
        return SAMPLE_UNDERRUN
    if t_us < traj_t[head % cap]:
        return SAMPLE_BEFORE
    while head + 1 < tail and traj_t[(head + 1) % cap] <= t_us:
        head += 1
    state[G_TRAJ_HEAD] = head
    if head + 1 >= tail:
        return SAMPLE_UNDERRUN
    if state[G_SEG_HEAD] != head or state[G_SEG_TAIL] != tail:
        _segment_coefficients(traj_t, traj_p, traj_v, state, head, base, tail)
    span_us = state[G_SEG_SPAN_US]
    h = span_us * 1e-6
    s = (t_us - state[G_SEG_T0_US]) / span_us
    for ax in range(2):
        c0 = state[G_SEG_COEF + 4 * ax]
        c1 = state[G_SEG_COEF + 4 * ax + 1]
        c2 = state[G_SEG_COEF + 4 * ax + 2]
        c3 = state[G_SEG_COEF + 4 * ax + 3]
        out[ax] = c0 + s * (c1 + s * (c2 + s * c3))
        out[2 + ax] = (c1 + s * (2.0 * c2 + 3.0 * s * c3)) / h
        out[4 + ax] = (2.0 * c2 + 6.0 * s * c3) / (h * h)
    return SAMPLE_OK


@_inline
def _ramp_velocity(state, sb, v_goal, amax, dt):
    """Move the reference velocity toward ``v_goal`` under ``amax``; integrate the reference."""
    v = state[sb + A_REF_VEL]
    dv = v_goal - v
    lim = amax * dt
    if dv > lim:
        dv = lim
    elif dv < -lim:
        dv = -lim
    state[sb + A_REF_VEL] = v + dv
    state[sb + A_REF_ACC] = dv / dt
    state[sb + A_REF] += (v + 0.5 * dv) * dt
    return v + dv


@_inline
def _slew_profile(state, sb, vmax, amax, dt):
    """Advance the time-optimal profile toward the target; return True once on it."""
    d = state[sb + A_TARGET] - state[sb + A_REF]
    v = state[sb + A_REF_VEL]
    ad = abs(d)
    # fastest velocity from which a stop at the target is still possible
    v_goal = min(vmax, math.sqrt(2.0 * amax * ad))
    if d < 0:
        v_goal = -v_goal
    dv = v_goal - v
    lim = amax * dt
    if dv > lim:
        dv = lim
    elif dv < -lim:
        dv = -lim
    v_new = v + dv
    if ad <= abs(v_new) * dt or ad < 1e-12:
        state[sb + A_REF] = state[sb + A_TARGET]
        state[sb + A_REF_ACC] = -v / dt if abs(v) < lim else 0.0
        state[sb + A_REF_VEL] = 0.0
        return True
    state[sb + A_REF_VEL] = v_new
    state[sb + A_REF_ACC] = dv / dt
    state[sb + A_REF] += (v + 0.5 * dv) * dt
    return False


@_inline
def _reference(state, params, sb, pb, a, sample_code, sample, dt):
    """Update the reference of one axis for this tick; return event bits."""
    ev = 0
    st = int(state[sb + A_STATE])
    if st in (OFF, FAULT):
        state[sb + A_REF] = state[sb + A_ENC]
        state[sb + A_REF_VEL] = 0.0
        state[sb + A_REF_ACC] = 0.0
        state[sb + A_TARGET] = state[sb + A_ENC]
    elif st == HOLDING:
        state[sb + A_REF_VEL] = 0.0
        state[sb + A_REF_ACC] = 0.0
    elif st == SLEWING:
        done = _slew_profile(state, sb, params[pb + P_VMAX], params[pb + P_AMAX], dt)
        if done and abs(state[sb + A_ERR]) < params[pb + P_SETTLE_AS] * ARCSEC:
            _apply(state, sb, EVT_ARRIVED)
            ev |= EV_ARRIVED
    elif st == TRACKING:
        if sample_code == SAMPLE_OK:
            state[sb + A_REF] = sample[a]
            state[sb + A_REF_VEL] = sample[2 + a]
            state[sb + A_REF_ACC] = sample[4 + a]
        elif sample_code == SAMPLE_BEFORE:
            state[sb + A_REF_VEL] = 0.0
            state[sb + A_REF_ACC] = 0.0
        else:
            _apply(state, sb, EVT_UNDERRUN)
            ev |= EV_UNDERRUN
            _ramp_velocity(state, sb, 0.0, params[pb + P_AMAX], dt)
    elif st == MANUAL:
        _ramp_velocity(state, sb, state[sb + A_MANUAL_RATE], params[pb + P_AMAX], dt)
    elif st == STOPPING:
        v = _ramp_velocity(state, sb, 0.0, params[pb + P_AMAX], dt)
        if v == 0.0:
            _apply(state, sb, EVT_STOPPED)
    return ev


@_inline
def _control(state, params, sb, pb, dt, k):
    """Run the cascaded position/velocity loops; return the current command (A)."""
    e = state[sb + A_REF] - state[sb + A_ENC]
    state[sb + A_ERR] = e
    st = int(state[sb + A_STATE])
    if st in (OFF, FAULT):
        state[sb + A_INT_POS] = 0.0
        state[sb + A_INT_VEL] = 0.0
        state[sb + A_VEL_CMD] = state[sb + A_VEL_EST]
        state[sb + A_PREV_EV] = 0.0
        return 0.0
    # position loop (PI) with velocity feed-forward
    vmax = params[pb + P_CTRL_VMAX]
    v_unsat = (
        params[pb + P_VFF] * state[sb + A_REF_VEL]
        + params[pb + P_KP] * e
        + params[pb + P_KI] * state[sb + A_INT_POS]
    )
    v_cmd = min(max(v_unsat, -vmax), vmax)
    # integral separation: the position integrator only works near the reference,
    # so a large transient does not leave a slowly-unwinding tail behind
    if abs(e) < params[pb + P_INT_ZONE] and (v_cmd == v_unsat or (v_unsat > vmax) == (e < 0)):
        state[sb + A_INT_POS] += e * dt
    # acceleration limit on the velocity command
    v_prev = state[sb + A_VEL_CMD]
    dv_lim = params[pb + P_CTRL_AMAX] * dt
    v_cmd = min(max(v_cmd, v_prev - dv_lim), v_prev + dv_lim)
    state[sb + A_VEL_CMD] = v_cmd
    # velocity loop (PID on the error) with acceleration feed-forward
    ev = v_cmd - state[sb + A_VEL_EST]
    imax = params[pb + P_I_MAX]
    # friction feed-forward on the commanded velocity, same smoothing as the plant model
    x = v_cmd * k[K_INV_VS]
    x = min(max(x, -1.0), 1.0)
    i_unsat = (
        (params[pb + P_AFF] * params[pb + P_J_FF] * state[sb + A_REF_ACC] + params[pb + P_FRIC_FF] * x)
        * k[K_INV_KT]
        + params[pb + P_KV] * ev
        + params[pb + P_KVI] * state[sb + A_INT_VEL]
        + params[pb + P_KVD] * (ev - state[sb + A_PREV_EV]) / dt
    )
    state[sb + A_PREV_EV] = ev
    i_cmd = min(max(i_unsat, -imax), imax)
    if i_cmd == i_unsat or (i_unsat > imax) == (ev < 0):
        state[sb + A_INT_VEL] += ev * dt
    return i_cmd


@_inline
def _watchdog(state, params, sb, pb, mount_faults):
    """Return the fault bits that trip on this axis now (0 when healthy)."""
    f = mount_faults
    if params[pb + P_INJ_ENC] != 0.0:
        f |= FAULT_ENCODER
    if abs(state[sb + A_CUR]) > params[pb + P_I_TRIP]:
        f |= FAULT_OVERCURRENT
    if state[sb + A_TEMP] > params[pb + P_T_MAX]:
        f |= FAULT_OVERTEMP
    st = int(state[sb + A_STATE])
    if st != OFF and st != FAULT:
        if abs(state[sb + A_ERR]) > params[pb + P_FERR_MAX]:
            f |= FAULT_FOLLOWING
        enc = state[sb + A_ENC]
        v = state[sb + A_REF_VEL]
        # beyond a limit and still driving outward (reset then a move back stays possible)
        if (enc < params[pb + P_POS_MIN] and v < 0.0) or (enc > params[pb + P_POS_MAX] and v > 0.0):
            f |= FAULT_LIMIT
    return f


@_inline
def _glitch(tick, salt, p, size):
    """Return this tick's injected encoder error in counts: ±size with probability p, else 0.

    A counter-based hash (splitmix64 of the tick and the axis), not a random generator:
    the same run glitches at the same ticks, whatever the block sizes.
    """
    x = np.uint64(int(tick)) * np.uint64(0x9E3779B97F4A7C15) + np.uint64(salt)
    x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    x = x ^ (x >> np.uint64(31))
    u = float(x >> np.uint64(11)) * (1.0 / 9007199254740992.0)  # 53 bits → [0, 1)
    if u >= p:
        return 0.0
    return size if u < 0.5 * p else -size


@_inline
def _degrade(state, params, sb, pb, dt):
    """Grow the injected degradations of one axis by one tick; return the rattling torque (N·m)."""
    h = dt * PER_HOUR
    state[sb + A_FRIC_INJ] += params[pb + P_INJ_FRIC_GROWTH] * h
    state[sb + A_HEAT_INJ] += params[pb + P_INJ_HEAT_GROWTH] * h
    amp = state[sb + A_RES_AMP] + params[pb + P_INJ_RES_GROWTH] * h
    state[sb + A_RES_AMP] = amp
    if amp == 0.0:
        return 0.0
    ph = state[sb + A_RES_PHASE] + TWO_PI * params[pb + P_INJ_RES_HZ] * dt
    if ph > TWO_PI:
        ph -= TWO_PI
    state[sb + A_RES_PHASE] = ph
    return amp * math.sin(ph)


@_inline
def _sense(state, params, sb, pb, dt, k):
    """Read the absolute encoder (unless faulted) and update the velocity estimate."""
    if params[pb + P_INJ_ENC] == 0.0:
        counts = math.floor(state[sb + A_POS_M] * k[K_CPR] + 0.5)
        if k[K_GLITCH_P] > 0.0:
            counts += _glitch(state[G_TICK], sb, k[K_GLITCH_P], params[pb + P_INJ_GLITCH_COUNTS])
        state[sb + A_ENC_COUNTS] = counts
        state[sb + A_ENC] = counts * k[K_RPC]
    enc = state[sb + A_ENC]
    raw_v = (enc - state[sb + A_PREV_ENC]) / dt
    state[sb + A_PREV_ENC] = enc
    state[sb + A_VEL_EST] += k[K_BETA_V] * (raw_v - state[sb + A_VEL_EST])


@_inline
def _plant(state, params, sb, pb, i_cmd, dt, ambient_c, k, t_rattle):
    """Integrate one axis over one tick; return the electrical power drawn (W).

    ``t_rattle`` is an injected disturbance torque on the load (a loosened part), N·m.
    """
    cur = state[sb + A_CUR]
    cur += (i_cmd - cur) * k[K_ALPHA_I]
    state[sb + A_CUR] = cur
    state[sb + A_CUR_CMD] = i_cmd
    pm = state[sb + A_POS_M]
    vm = state[sb + A_VEL_M]
    pl = state[sb + A_POS_L]
    vl = state[sb + A_VEL_L]
    kt = k[K_KT_EFF]
    t_motor = kt * cur + params[pb + P_COG] * math.sin(params[pb + P_COG_N] * pm)
    t_spring = params[pb + P_K] * (pm - pl) + params[pb + P_C] * (vm - vl)
    t_grav = params[pb + P_GRAV] * math.cos(pl) if params[pb + P_GRAV] != 0.0 else 0.0
    dt_jm = k[K_DT_JM]
    vm_free = vm + (t_motor - t_spring - params[pb + P_VISC] * vm) * dt_jm
    fc = max(params[pb + P_COULOMB] + state[sb + A_FRIC_INJ], 0.0)
    st = int(state[sb + A_STATE])
    if st in (OFF, FAULT):
        # holding brake: exact stiction (implicit clamp), it never creeps
        dv_c = (fc + params[pb + P_BRAKE]) * dt_jm
        if vm_free > dv_c:
            vm = vm_free - dv_c
        elif vm_free < -dv_c:
            vm = vm_free + dv_c
        else:
            vm = 0.0
    else:
        # Coulomb friction solved implicitly, linear below the smoothing velocity:
        # no stick-slip hunting under integral action, stable at any step
        dv_c = fc * dt_jm
        v_s = params[pb + P_FRIC_VS]
        vm = vm_free / (1.0 + dv_c * k[K_INV_VS])
        if vm > v_s:
            vm = vm_free - dv_c
        elif vm < -v_s:
            vm = vm_free + dv_c
    vl = vl + (t_spring - t_grav + t_rattle) * k[K_DT_JL]
    state[sb + A_VEL_M] = vm
    state[sb + A_VEL_L] = vl
    state[sb + A_POS_M] = pm + dt * vm
    state[sb + A_POS_L] = pl + dt * vl
    state[sb + A_TORQUE] = t_motor
    # winding temperature: C·dT/dt = I²R − (T − T_amb)/R_th, C = τ/R_th
    r_th = params[pb + P_RTH]
    heat = cur * cur * params[pb + P_R_OHM] + state[sb + A_HEAT_INJ]
    temp = state[sb + A_TEMP]
    state[sb + A_TEMP] = temp + (heat * r_th - (temp - ambient_c)) * k[K_DT_TAU_TH]
    power = heat + kt * cur * vm
    state[sb + A_POWER] = power
    return power


@_inline
def _peak(state, sb):
    """Track the peak |following error| (every tick: a peak must not be missed)."""
    err_as = abs(state[sb + A_ERR]) / ARCSEC
    if err_as > state[sb + A_ERR_PEAK_AS]:
        state[sb + A_ERR_PEAK_AS] = err_as


@_inline
def _derived(state, sb):
    """Refresh the human-facing copies (degrees, arcseconds) of one axis.

    Done per tick only while a stream wants per-tick values, else once per block,
    so simulated time does not pay for conversions nobody reads.
    """
    state[sb + A_ERR_AS] = state[sb + A_ERR] / ARCSEC
    state[sb + A_POS_DEG] = state[sb + A_ENC] * RAD_TO_DEG
    state[sb + A_VEL_DEG_S] = state[sb + A_VEL_EST] * RAD_TO_DEG
    state[sb + A_LOAD_ERR_AS] = (state[sb + A_REF] - state[sb + A_POS_L]) / ARCSEC
    state[sb + A_TWIST_AS] = (state[sb + A_POS_M] - state[sb + A_POS_L]) / ARCSEC


@_inline
def _clock(state, params):
    """Advance true and mount time by one tick, handling the PPS edge; return event bits."""
    ev = 0
    state[G_TICK] += 1.0
    state[G_TRUE_US] += TICK_US
    if params[Q_INJ_DRIFT_GROWTH] != 0.0:
        state[G_DRIFT_INJ_PPM] += params[Q_INJ_DRIFT_GROWTH] * (TICK_S * PER_HOUR)
    drift_ppm = params[Q_DRIFT_PPM] + state[G_DRIFT_INJ_PPM]
    frac = state[G_MOUNT_FRAC_US] + TICK_US * (1.0 + drift_ppm * 1e-6)
    whole = math.floor(frac)
    state[G_MOUNT_US] += whole
    state[G_MOUNT_FRAC_US] = frac - whole
    state[G_PPS_COUNTDOWN] -= 1.0
    if state[G_PPS_COUNTDOWN] <= 0.0:
        state[G_PPS_COUNTDOWN] = TICKS_PER_SECOND
        ev |= EV_PPS
        state[G_PPS_COUNT] += 1.0
        state[G_PPS_ERR_US] = state[G_MOUNT_US] + state[G_MOUNT_FRAC_US] - state[G_TRUE_US]
        if state[G_PENDING_UTC_S] >= 0.0:
            state[G_MOUNT_US] = state[G_PENDING_UTC_S] * 1e6
            state[G_MOUNT_FRAC_US] = 0.0
            state[G_PENDING_UTC_S] = -1.0
            state[G_SYNC_COUNT] += 1.0
            status = int(state[G_STATUS])
            status = (status | STATUS_TIME_SYNCED) & ~STATUS_SYNC_ARMED
            state[G_STATUS] = status
            ev |= EV_SYNC
    return ev


@_inline
def _mount_state(state):
    """Derive the mount state from its axes (see states module docstring)."""
    s0 = int(state[STATE_AXIS0 + A_STATE])
    s1 = int(state[STATE_AXIS0 + AXIS_STRIDE + A_STATE])
    if s0 == FAULT or s1 == FAULT:
        return FAULT
    for s in (TRACKING, SLEWING, MANUAL, STOPPING, HOLDING):
        if s0 == s or s1 == s:
            return s
    return OFF


@_inline
def _block_constants(state, params, dt):
    """Return the per-axis constants (``K_*``) derived from the parameters for one block."""
    k = np.empty((2, N_K))
    for a in range(2):
        pb = PARAM_AXIS0 + a * AXIS_STRIDE
        cpr = math.ldexp(1.0, int(params[pb + P_ENC_BITS])) / TWO_PI
        k[a, K_CPR] = cpr
        k[a, K_RPC] = 1.0 / cpr
        k[a, K_BETA_V] = dt / (params[pb + P_TAU_V] + dt)
        k[a, K_ALPHA_I] = dt / (params[pb + P_TAU_I] + dt)
        k[a, K_DT_JM] = dt / params[pb + P_JM]
        k[a, K_DT_JL] = dt / params[pb + P_JL]
        k[a, K_INV_KT] = 1.0 / params[pb + P_KT]
        k[a, K_INV_VS] = 1.0 / params[pb + P_FRIC_VS]
        k[a, K_DT_TAU_TH] = dt / params[pb + P_TAU_TH]
        k[a, K_KT_EFF] = params[pb + P_KT] * (1.0 - params[pb + P_INJ_WINDING])
        k[a, K_GLITCH_P] = params[pb + P_INJ_GLITCH_RATE] * dt
        sb = STATE_AXIS0 + a * AXIS_STRIDE
        growing = (params[pb + P_INJ_FRIC_GROWTH] != 0.0 or params[pb + P_INJ_RES_GROWTH] != 0.0
                   or params[pb + P_INJ_HEAT_GROWTH] != 0.0 or state[sb + A_RES_AMP] != 0.0)
        k[a, K_DEGRADE] = 1.0 if growing else 0.0
    return k


@_jit
def step(state, params, traj_t, traj_p, traj_v, n_ticks, trace, trace_src, trace_dst):
    """Advance the mount by ``n_ticks`` ticks of 100 µs; return the events seen (EV_* bits).

    ``trace`` (n_ticks × width, or any 2-D array when ``trace_src`` is empty)
    receives ``state[trace_src[j]]`` in column ``trace_dst[j]`` after every tick.
    """
    kk = _block_constants(state, params, TICK_S)
    return _ticks(state, params, traj_t, traj_p, traj_v, n_ticks, trace, trace_src, trace_dst,
                  kk, np.zeros(6))


# The tick loop is compiled without reference counting: with it, every array handed to an
# inlined helper costs an atomic increment and decrement per tick, which measured 75 % of
# the step's time (perf). It allocates nothing; `step` hands it its scratch arrays.
@njit(cache=True, nogil=True, fastmath=_FASTMATH, _nrt=False)
def _ticks(state, params, traj_t, traj_p, traj_v, n_ticks, trace, trace_src, trace_dst, kk,
           sample):
    dt = TICK_S
    events = 0
    n_trace = trace_src.shape[0]
    for n in range(n_ticks):
        events |= _clock(state, params)
        t_us = state[G_MOUNT_US] + state[G_MOUNT_FRAC_US]
        # watchdog inputs common to both axes
        tick = state[G_TICK]
        if params[Q_INJECT_HB_MISS] == 0.0:
            state[G_HB_LAST_TICK] = tick
        mount_faults = int(state[G_FAULTS])
        if (tick - state[G_HB_LAST_TICK]) * dt > params[Q_HB_TIMEOUT_S]:
            mount_faults |= FAULT_HEARTBEAT
        if state[G_BUS_V] > params[Q_OVERVOLTAGE_V]:
            mount_faults |= FAULT_OVERVOLTAGE
        state[G_FAULTS] = mount_faults
        # one trajectory sample shared by both axes
        code = SAMPLE_UNDERRUN
        s0 = int(state[STATE_AXIS0 + A_STATE])
        s1 = int(state[STATE_AXIS0 + AXIS_STRIDE + A_STATE])
        if s0 == TRACKING or s1 == TRACKING:
            code = _hermite_sample(traj_t, traj_p, traj_v, state, t_us, sample)
            if code == SAMPLE_OK:
                state[G_TRAJ_REF_AZ] = sample[0]
                state[G_TRAJ_REF_EL] = sample[1]
        p_total = 0.0
        ambient = params[Q_AMBIENT_C]
        for a in range(2):
            sb = STATE_AXIS0 + a * AXIS_STRIDE
            pb = PARAM_AXIS0 + a * AXIS_STRIDE
            k = kk[a]
            _sense(state, params, sb, pb, dt, k)
            ev = _reference(state, params, sb, pb, a, code, sample, dt)
            if ev & EV_UNDERRUN and not events & EV_UNDERRUN:
                state[G_TRAJ_UNDERRUNS] += 1.0
                state[G_STATUS] = int(state[G_STATUS]) | STATUS_UNDERRUN
            events |= ev
            i_cmd = _control(state, params, sb, pb, dt, k)
            f = _watchdog(state, params, sb, pb, mount_faults)
            if f != 0:
                state[sb + A_FAULTS] = int(state[sb + A_FAULTS]) | f
                if int(state[sb + A_STATE]) != FAULT:
                    _apply(state, sb, EVT_FAULT)
                    events |= EV_FAULT
            if int(state[sb + A_STATE]) == FAULT:
                i_cmd = 0.0
            t_rattle = _degrade(state, params, sb, pb, dt) if k[K_DEGRADE] != 0.0 else 0.0
            p_total += _plant(state, params, sb, pb, i_cmd, dt, ambient, k, t_rattle)
            _peak(state, sb)
            if n_trace > 0:
                _derived(state, sb)
        # DC bus: supply through its resistance (a diode: it only sources), chopper above its threshold
        v_bus = state[G_BUS_V]
        i_sup = (params[Q_SUPPLY_V] - v_bus) / params[Q_SUPPLY_R]
        if i_sup < 0.0:
            i_sup = 0.0
        p_sup = v_bus * i_sup
        p_ch = 0.0
        status = int(state[G_STATUS])
        if v_bus > params[Q_CHOPPER_ON_V]:
            p_ch = v_bus * v_bus / params[Q_CHOPPER_R]
            status |= STATUS_CHOPPER
        else:
            status &= ~STATUS_CHOPPER
        state[G_BUS_V] = v_bus + dt * (p_sup - p_total - p_ch) / (params[Q_BUS_C] * v_bus)
        state[G_SUPPLY_W] = p_sup
        state[G_CHOPPER_W] = p_ch
        state[G_REGEN_J] += p_ch * dt
        mstate = _mount_state(state)
        state[G_MOUNT_STATE] = mstate
        if mstate == FAULT:
            status |= STATUS_FAULT
        else:
            status &= ~STATUS_FAULT
        state[G_STATUS] = status
        for j in range(n_trace):
            trace[n, trace_dst[j]] = state[trace_src[j]]
    for a in range(2):
        _derived(state, STATE_AXIS0 + a * AXIS_STRIDE)
    state[G_EVENTS] = events
    return events


def initial_state(params: np.ndarray, *, start_us: int, az_rad: float = 0.0,
                  el_rad: float = math.radians(20.0)) -> np.ndarray:
    """Return a state array at rest: drives off, brakes on, clocks at ``start_us`` (µs since 1970).

    ``start_us`` is rounded down to a whole tick so PPS edges fall on ticks.
    The elevation tube starts in its gravity-loaded equilibrium (static twist).
    """
    state = np.zeros(STATE_SIZE)
    start_us = int(start_us) // TICK_US * TICK_US
    state[G_TRUE_US] = float(start_us)
    state[G_MOUNT_US] = float(start_us)
    state[G_PENDING_UTC_S] = -1.0
    state[G_PPS_COUNTDOWN] = (1_000_000 - start_us % 1_000_000) // TICK_US
    state[G_SEG_HEAD] = -1.0
    state[G_BUS_V] = params[Q_SUPPLY_V]
    for a, pos in enumerate((az_rad, el_rad)):
        sb = STATE_AXIS0 + a * AXIS_STRIDE
        pb = PARAM_AXIS0 + a * AXIS_STRIDE
        state[sb + A_POS_M] = pos
        twist = params[pb + P_GRAV] * math.cos(pos) / params[pb + P_K]
        state[sb + A_POS_L] = pos - twist
        counts_per_rad = math.ldexp(1.0, int(params[pb + P_ENC_BITS])) / TWO_PI
        enc = math.floor(pos * counts_per_rad + 0.5) / counts_per_rad
        state[sb + A_ENC] = enc
        state[sb + A_PREV_ENC] = enc
        state[sb + A_REF] = enc
        state[sb + A_TARGET] = enc
        state[sb + A_TEMP] = params[Q_AMBIENT_C]
        state[sb + A_STATE] = OFF
        _derived(state, sb)
    return state
