"""Name every slot of the state and parameter arrays the compiled step works on.

The physics step (`physics.step`) reads and writes two float64 arrays: ``state``
(what the mount *is*: positions, currents, temperatures, states, clock) and
``params`` (what an operator may *set*: inertias, gains, limits, fault injection).
This module is the one place that gives each slot its index, name, unit and
default. The compiled code uses the integer constants; the ASTCom registry, the
configuration loader and the documentation use the tables `STATE_SLOTS` and
`PARAM_SLOTS`.

Layout: a global block first, then one block per axis (azimuth then elevation)
of ``AXIS_STRIDE`` slots each. Inside a block the per-axis constants (``A_*``
for state, ``P_*`` for parameters) are offsets from the block start, so an axis
slot is ``STATE_AXIS0 + axis * AXIS_STRIDE + A_POS``. Integers (states, bits,
counters) are stored as float64 holding an exact integer.

Every slot also carries its ASTCom wire type (`Slot.type`): positions, angles in
rad, rates, times, ticks and parameters are ``f64``/``i64``; quantities the real
controller *measures* (currents from its ADC, temperatures, voltages, powers and
energies, torque from the current, the arcsecond error signals) are ``f32``, as a
single-precision MCU reports them. The state array itself stays float64: the
endpoint rounds to f32 when it reads or streams such a slot.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = [
    "AXES",
    "AXIS_STRIDE",
    "PARAM_SLOTS",
    "STATE_SLOTS",
    "Slot",
    "TICK_S",
    "TICK_US",
    "default_params",
    "param_index",
    "state_index",
]

TICK_US = 100  # one controller tick: 10 kHz
TICK_S = TICK_US * 1e-6
ARCSEC = math.pi / 180.0 / 3600.0  # radians per arcsecond
AXES = ("az", "el")
AXIS_STRIDE = 48


@dataclass(frozen=True)
class Slot:
    """One named slot of the state or parameter array."""

    name: str
    index: int
    unit: str
    doc: str
    default: float = 0.0
    kind: str = "signal"  # signal (f64 or f32) | status (i64) | parameter (f64, rw)
    traced: bool = False  # may be streamed per tick
    type: str = "f64"  # ASTCom wire type: f64, f32 (measured quantities) or i64 (status)


# ---------------------------------------------------------------- global state
G_TICK = 0  # ticks since start
G_TRUE_US = 1  # true UTC time of the current tick, µs since 1970 (the GPS/PPS truth)
G_MOUNT_US = 2  # mount clock, integer part, µs since 1970
G_MOUNT_FRAC_US = 3  # mount clock fractional µs (keeps drift exact)
G_PENDING_UTC_S = 4  # UTC second to apply at the next PPS edge, -1 if none
G_PPS_COUNT = 5
G_PPS_ERR_US = 6  # mount clock minus true second at the last PPS edge
G_MOUNT_STATE = 7
G_STATUS = 8
G_FAULTS = 9  # mount-level fault bits (heartbeat, overvoltage)
G_TRAJ_HEAD = 10  # index counter of the oldest point still needed
G_TRAJ_TAIL = 11  # index counter one past the newest point
G_TRAJ_LATE = 12
G_TRAJ_ACCEPTED = 13
G_TRAJ_UNDERRUNS = 14
G_TRAJ_OUT_OF_RANGE = 15
G_BUS_V = 16
G_SUPPLY_W = 17
G_CHOPPER_W = 18
G_REGEN_J = 19
G_HB_LAST_TICK = 20
G_TRAJ_LAST_US = 21  # time tag of the newest point in the buffer
G_EVENTS = 22  # bits of events seen during the last block (see states.EV_*)
G_SYNC_COUNT = 23
G_TRAJ_REF_AZ = 24
G_TRAJ_REF_EL = 25
G_TRAJ_BASE = 26  # index counter of the first point since traj.init (tangent estimates)
G_PPS_COUNTDOWN = 27  # ticks until the next PPS edge (true time on a whole second)
G_SEG_HEAD = 28  # trajectory segment whose Hermite coefficients are cached (-1: none)
G_SEG_TAIL = 29  # buffer tail when they were computed (a new point may change the end tangent)
G_SEG_T0_US = 30
G_SEG_SPAN_US = 31
G_SEG_COEF = 32  # 8 slots: per axis c0..c3 of p(s) = c0 + c1·s + c2·s² + c3·s³, s in [0, 1)
G_DRIFT_INJ_PPM = 40  # clock drift added by the injected drift growth, ppm
G_TRAJ_REPLACES = 41  # traj.replace_from calls applied since traj.init
G_TRAJ_REPLACE_REFUSED = 42  # traj.replace_from calls refused (too late) since traj.init
G_TRAJ_DROPPED = 43  # buffered points dropped by traj.replace_from since traj.init
G_TRAJ_REPLACE_LEAD_US = 44  # lead (from - mount time) of the last applied replace_from, µs
STATE_AXIS0 = 64

# ----------------------------------------------------------- per-axis state
A_POS_M = 0  # motor/axis angle (true), rad — where the encoder sits
A_VEL_M = 1
A_POS_L = 2  # load (optical tube) angle (true), rad
A_VEL_L = 3
A_CUR = 4  # motor current, A
A_CUR_CMD = 5
A_ENC = 6  # encoder reading, rad (quantised)
A_ENC_COUNTS = 7
A_VEL_EST = 8  # filtered velocity from the encoder, rad/s
A_REF = 9  # position reference, rad
A_REF_VEL = 10
A_REF_ACC = 11
A_ERR = 12  # following error reference - encoder, rad
A_ERR_AS = 13  # same, arcsec
A_LOAD_ERR_AS = 14  # reference - true tube angle, arcsec
A_INT_POS = 15
A_INT_VEL = 16
A_VEL_CMD = 17
A_TEMP = 18  # winding temperature, °C
A_STATE = 19
A_FAULTS = 20
A_TARGET = 21  # slew target, rad
A_MANUAL_RATE = 22  # manual move rate, rad/s
A_TORQUE = 23  # motor electromagnetic torque incl. cogging, N·m
A_POWER = 24  # electrical power drawn by the winding, W (negative = regen)
A_PREV_ENC = 25
A_POS_DEG = 26
A_VEL_DEG_S = 27
A_ERR_PEAK_AS = 28  # peak |following error| since last read reset
A_TWIST_AS = 29  # motor - load angle, arcsec
A_PREV_EV = 30  # previous velocity error (velocity-loop D term)
# Injected degradations (docs/mount-emulator.md, "Fault injection"): what has grown so far
A_FRIC_INJ = 31  # extra Coulomb friction, N·m
A_RES_AMP = 32  # amplitude of the rattling torque of a loosened part, N·m
A_RES_PHASE = 33  # its phase, rad
A_HEAT_INJ = 34  # extra heat in the winding, W

# --------------------------------------------------------- global parameters
Q_DRIFT_PPM = 0
Q_HB_TIMEOUT_S = 1
Q_INJECT_HB_MISS = 2
Q_SUPPLY_V = 3
Q_SUPPLY_R = 4
Q_BUS_C = 5
Q_CHOPPER_ON_V = 6
Q_CHOPPER_R = 7
Q_OVERVOLTAGE_V = 8
Q_AMBIENT_C = 9
Q_LATE_MARGIN_US = 10
Q_INJ_DRIFT_GROWTH = 11  # ppm per hour
Q_REPLACE_MIN_LEAD_US = 12  # traj.replace_from refuses a time closer to the clock than this
PARAM_AXIS0 = 16

# ------------------------------------------------------ per-axis parameters
P_JM = 0
P_JL = 1
P_K = 2
P_C = 3
P_KT = 4
P_I_MAX = 5
P_TAU_I = 6
P_R_OHM = 7
P_VISC = 8
P_COULOMB = 9
P_COG = 10
P_COG_N = 11
P_GRAV = 12
P_ENC_BITS = 13
P_KP = 14
P_KI = 15
P_KV = 16
P_KVI = 17
P_KVD = 18
P_TAU_V = 19
P_J_FF = 20
P_VFF = 21
P_AFF = 22
P_VMAX = 23
P_AMAX = 24
P_CTRL_VMAX = 25
P_CTRL_AMAX = 26
P_FERR_MAX = 27
P_POS_MIN = 28
P_POS_MAX = 29
P_I_TRIP = 30
P_T_MAX = 31
P_RTH = 32
P_TAU_TH = 33
P_INJ_ENC = 34
P_BRAKE = 35
P_SETTLE_AS = 36
P_FRIC_VS = 37
P_FRIC_FF = 38
P_INT_ZONE = 39
# Fault injection of gradual degradations (the existing P_INJ_ENC freezes the encoder)
P_INJ_FRIC_GROWTH = 40  # N·m per hour
P_INJ_WINDING = 41  # fraction of the torque constant lost
P_INJ_RES_GROWTH = 42  # N·m per hour
P_INJ_RES_HZ = 43
P_INJ_GLITCH_RATE = 44  # glitches per second
P_INJ_GLITCH_COUNTS = 45
P_INJ_HEAT_GROWTH = 46  # W per hour

_DEG = math.pi / 180.0


def _axis_param_defaults(axis: str) -> dict[int, float]:
    """Return the defaults of one axis of a direct-drive 0.5 m-class mount.

    Azimuth carries the fork and tube (more inertia, softer: ≈ 18 Hz locked-rotor
    resonance); elevation carries the tube only (≈ 25 Hz) and sees a gravity
    imbalance. Gains are tuned on these plants (see docs/mount-emulator.md).
    """
    az = axis == "az"
    jm, jl = (6.0, 30.0) if az else (3.0, 12.0)
    f_res = 18.0 if az else 25.0
    k = (2 * math.pi * f_res) ** 2 / (1 / jm + 1 / jl)
    mu = 1 / (1 / jm + 1 / jl)
    c = 2 * 0.05 * (2 * math.pi * f_res) * mu  # 5 % structural damping
    kt = 12.0
    jt = jm + jl
    wv = 2 * math.pi * 20.0  # velocity-loop crossover on the rigid plant
    return {
        P_JM: jm,
        P_JL: jl,
        P_K: k,
        P_C: c,
        P_KT: kt,
        P_I_MAX: 10.0,
        P_TAU_I: 0.25e-3,
        P_R_OHM: 1.6,
        P_VISC: 4.0,
        P_COULOMB: 3.0 if az else 2.0,
        P_COG: 0.4,
        P_COG_N: 96.0,
        P_GRAV: 0.0 if az else 6.0,
        P_ENC_BITS: 26.0,
        P_KP: 2 * math.pi * 5.0,
        P_KI: 4.0,
        P_KV: jt * wv / kt,
        P_KVI: jt * wv / kt * wv / 5.0,
        P_KVD: 0.0,
        P_TAU_V: 0.25e-3,
        P_J_FF: jt,
        P_VFF: 1.0,
        P_AFF: 1.0,
        P_VMAX: 6.0 * _DEG,
        P_AMAX: 3.0 * _DEG,
        P_CTRL_VMAX: 8.0 * _DEG,
        P_CTRL_AMAX: 20.0 * _DEG,
        P_FERR_MAX: 0.5 * _DEG,
        P_POS_MIN: -270.0 * _DEG if az else 0.0,
        P_POS_MAX: 270.0 * _DEG if az else 90.0 * _DEG,
        P_I_TRIP: 12.0,
        P_T_MAX: 110.0,
        P_RTH: 0.8,
        P_TAU_TH: 900.0,
        P_INJ_ENC: 0.0,
        P_BRAKE: 60.0,
        P_SETTLE_AS: 1.0,
        P_FRIC_VS: 1e-4,
        P_INT_ZONE: 2.0 * ARCSEC,
        P_FRIC_FF: 0.8 * (3.0 if az else 2.0),
        P_INJ_FRIC_GROWTH: 0.0,
        P_INJ_WINDING: 0.0,
        P_INJ_RES_GROWTH: 0.0,
        P_INJ_RES_HZ: f_res,
        P_INJ_GLITCH_RATE: 0.0,
        P_INJ_GLITCH_COUNTS: 1.0,
        P_INJ_HEAT_GROWTH: 0.0,
    }


_GLOBAL_STATE = [
    (G_TICK, "mount.tick", "tick", "Controller ticks since the emulator started", "status"),
    (G_TRUE_US, "time.true_us", "us", "True UTC of the current tick (the PPS truth), µs since 1970", "status"),
    (G_MOUNT_US, "time.mount_us", "us", "Mount clock: integer µs since 1970 UTC, drifts between syncs", "status"),
    (G_PENDING_UTC_S, "time.pending_utc_s", "s", "UTC second armed for the next PPS edge, -1 if none", "status"),
    (G_PPS_COUNT, "time.pps_count", "", "PPS edges seen", "status"),
    (G_PPS_ERR_US, "time.pps_error_us", "us", "Mount clock minus true second at the last PPS edge, before any sync", "signal"),
    (G_SYNC_COUNT, "time.sync_count", "", "Number of set_utc values applied on a PPS edge", "status"),
    (G_MOUNT_STATE, "mount.state", "", "Mount state (MountState: 0 off, 1 holding, 2 slewing, 3 tracking, 4 manual, 5 stopping, 6 fault)", "status"),
    (G_STATUS, "mount.status_bits", "", "Status bits (states.STATUS_*): 1 underrun, 2 trajectory started, 4 time synced, 8 sync armed, 16 fault, 32 chopper on", "status"),
    (G_FAULTS, "safety.mount_faults", "", "Mount-level latched fault bits (FAULT_HEARTBEAT, FAULT_OVERVOLTAGE)", "status"),
    (G_TRAJ_LATE, "traj.late", "", "Points rejected because their time tag was not in the future or not increasing", "status"),
    (G_TRAJ_ACCEPTED, "traj.accepted", "", "Points accepted since traj.init", "status"),
    (G_TRAJ_UNDERRUNS, "traj.underruns", "", "Underruns (no future point while tracking) since traj.init", "status"),
    (G_TRAJ_OUT_OF_RANGE, "traj.out_of_range", "", "Points rejected because they lie outside the axis limits", "status"),
    (G_TRAJ_LAST_US, "traj.last_t_us", "us", "Time tag of the newest point in the buffer (mount time)", "status"),
    (G_BUS_V, "power.bus_voltage", "V", "DC bus voltage", "signal"),
    (G_SUPPLY_W, "power.supply_power", "W", "Power drawn from the supply", "signal"),
    (G_CHOPPER_W, "power.chopper_power", "W", "Power burnt in the brake chopper resistor", "signal"),
    (G_REGEN_J, "power.regen_energy", "J", "Regenerated energy dissipated in the chopper since start", "signal"),
    (G_TRAJ_REF_AZ, "traj.ref_az", "rad", "Trajectory sample at the current tick, azimuth", "signal"),
    (G_TRAJ_REF_EL, "traj.ref_el", "rad", "Trajectory sample at the current tick, elevation", "signal"),
    (G_TRAJ_REPLACES, "traj.replaces", "", "traj.replace_from calls applied since traj.init", "status"),
    (G_TRAJ_REPLACE_REFUSED, "traj.replace_refused", "", "traj.replace_from calls refused since traj.init (time past or closer than traj.replace_min_lead_us)", "status"),
    (G_TRAJ_DROPPED, "traj.dropped", "", "Buffered points dropped by traj.replace_from since traj.init", "status"),
    (G_TRAJ_REPLACE_LEAD_US, "traj.replace_lead_us", "us", "Lead of the last applied traj.replace_from: its from_us minus the mount time it arrived at", "status"),
    (G_DRIFT_INJ_PPM, "time.injected_drift_ppm", "ppm", "Clock drift added so far by time.inject_drift_growth (fault injection)", "signal"),
]

_AXIS_STATE = [
    (A_ENC, "position", "rad", "Encoder position (quantised)", "signal"),
    (A_POS_DEG, "position_deg", "deg", "Encoder position in degrees", "signal"),
    (A_ENC_COUNTS, "encoder_counts", "count", "Raw absolute encoder counts", "status"),
    (A_VEL_EST, "velocity", "rad/s", "Velocity estimated from the encoder", "signal"),
    (A_VEL_DEG_S, "velocity_deg_s", "deg/s", "Velocity estimate in degrees per second", "signal"),
    (A_REF, "reference", "rad", "Position reference of the controller", "signal"),
    (A_REF_VEL, "reference_velocity", "rad/s", "Velocity reference (feed-forward)", "signal"),
    (A_REF_ACC, "reference_acceleration", "rad/s^2", "Acceleration reference (feed-forward)", "signal"),
    (A_ERR, "error", "rad", "Following error: reference minus encoder", "signal"),
    (A_ERR_AS, "error_arcsec", "arcsec", "Following error in arcseconds", "signal"),
    (A_ERR_PEAK_AS, "error_peak_arcsec", "arcsec", "Peak |following error| since last written 0", "signal"),
    (A_LOAD_ERR_AS, "load_error_arcsec", "arcsec", "Reference minus true tube angle (includes structural twist)", "signal"),
    (A_TWIST_AS, "twist_arcsec", "arcsec", "Structural twist: axis minus tube angle", "signal"),
    (A_POS_M, "true_position", "rad", "True axis angle (unquantised; emulator truth)", "signal"),
    (A_VEL_M, "true_velocity", "rad/s", "True axis angular velocity", "signal"),
    (A_POS_L, "load_position", "rad", "True tube angle", "signal"),
    (A_VEL_L, "load_velocity", "rad/s", "True tube angular velocity", "signal"),
    (A_CUR, "current", "A", "Motor current", "signal"),
    (A_CUR_CMD, "current_cmd", "A", "Current commanded by the velocity loop", "signal"),
    (A_TORQUE, "torque", "N*m", "Motor torque including cogging", "signal"),
    (A_POWER, "power", "W", "Electrical power into the winding (negative when regenerating)", "signal"),
    (A_TEMP, "temperature", "degC", "Winding temperature", "signal"),
    (A_VEL_CMD, "velocity_cmd", "rad/s", "Velocity command of the position loop", "signal"),
    (A_INT_POS, "int_position", "rad*s", "Position-loop integrator", "signal"),
    (A_INT_VEL, "int_velocity", "rad", "Velocity-loop integrator", "signal"),
    (A_STATE, "state", "", "Axis state (AxisState: 0 off, 1 holding, 2 slewing, 3 tracking, 4 manual, 5 stopping, 6 fault)", "status"),
    (A_FAULTS, "faults", "", "Latched fault bits (FAULT_*: 1 overcurrent, 2 overtemp, 4 encoder, 8 following error, 16 limit, 32 heartbeat, 64 overvoltage)", "status"),
    (A_TARGET, "target", "rad", "Slew target", "signal"),
    (A_MANUAL_RATE, "manual_rate", "rad/s", "Manual move rate", "signal"),
    (A_FRIC_INJ, "injected_friction", "N*m", "Coulomb friction added so far by inject_friction_growth (fault injection)", "signal"),
    (A_RES_AMP, "injected_resonance", "N*m", "Amplitude of the rattling torque grown so far by inject_resonance_growth (fault injection)", "signal"),
    (A_HEAT_INJ, "injected_heat", "W", "Winding heat added so far by inject_heat_growth (fault injection)", "signal"),
]

_GLOBAL_PARAMS = [
    (Q_DRIFT_PPM, "time.drift_ppm", "ppm", "Crystal frequency error of the mount clock", 2.0),
    (Q_HB_TIMEOUT_S, "safety.heartbeat_timeout", "s", "Watchdog trips when the controller heartbeat is missing this long", 0.005),
    (Q_INJECT_HB_MISS, "safety.inject_heartbeat_miss", "bool", "Fault injection: 1 stops the controller heartbeat", 0.0),
    (Q_SUPPLY_V, "power.supply_voltage", "V", "Supply (PSU) open-circuit voltage", 48.0),
    (Q_SUPPLY_R, "power.supply_resistance", "ohm", "Supply source resistance", 0.05),
    (Q_BUS_C, "power.bus_capacitance", "F", "DC bus capacitance", 0.02),
    (Q_CHOPPER_ON_V, "power.chopper_on_voltage", "V", "Brake chopper switches on above this bus voltage", 56.0),
    (Q_CHOPPER_R, "power.chopper_resistance", "ohm", "Brake chopper resistor", 4.0),
    (Q_OVERVOLTAGE_V, "safety.overvoltage", "V", "Watchdog trips above this bus voltage", 65.0),
    (Q_AMBIENT_C, "power.ambient_temperature", "degC", "Ambient temperature for the motor thermal model", 15.0),
    (Q_LATE_MARGIN_US, "traj.late_margin_us", "us", "A pushed point must be at least this far in the future", 0.0),
    (Q_REPLACE_MIN_LEAD_US, "traj.replace_min_lead_us", "us", "traj.replace_from refuses a from_us closer to the mount clock than this (the controller's documented minimum lead)", 20000.0),
    (Q_INJ_DRIFT_GROWTH, "time.inject_drift_growth", "ppm/h", "Fault injection: the clock's drift changes by this much per hour (a crystal warming or ageing); time.injected_drift_ppm holds what it added", 0.0),
]

_AXIS_PARAMS = [
    (P_JM, "inertia_motor", "kg*m^2", "Motor-side inertia (rotor, axis, encoder)"),
    (P_JL, "inertia_load", "kg*m^2", "Load-side inertia (tube, fork)"),
    (P_K, "stiffness", "N*m/rad", "Torsional stiffness between motor and load"),
    (P_C, "damping", "N*m*s/rad", "Structural damping between motor and load"),
    (P_KT, "torque_constant", "N*m/A", "Motor torque constant"),
    (P_I_MAX, "current_limit", "A", "Current command limit"),
    (P_TAU_I, "current_tau", "s", "Current-loop time constant (first-order lag)"),
    (P_R_OHM, "winding_resistance", "ohm", "Winding resistance (I²R heating)"),
    (P_VISC, "viscous_friction", "N*m*s/rad", "Viscous friction on the axis"),
    (P_COULOMB, "coulomb_friction", "N*m", "Coulomb (dry) friction on the axis"),
    (P_COG, "cogging", "N*m", "Cogging torque amplitude"),
    (P_COG_N, "cogging_periods", "1/rev", "Cogging periods per revolution of the motor"),
    (P_GRAV, "gravity_imbalance", "N*m", "Gravity imbalance torque at horizon (× cos of the tube angle)"),
    (P_ENC_BITS, "encoder_bits", "bit", "Absolute encoder resolution: 2^bits counts per revolution"),
    (P_KP, "kp", "1/s", "Position-loop proportional gain"),
    (P_KI, "ki", "1/s^2", "Position-loop integral gain"),
    (P_KV, "kv", "A*s/rad", "Velocity-loop proportional gain"),
    (P_KVI, "kvi", "A/rad", "Velocity-loop integral gain"),
    (P_KVD, "kvd", "A*s^2/rad", "Velocity-loop derivative gain"),
    (P_TAU_V, "velocity_filter_tau", "s", "Time constant of the velocity estimate low-pass"),
    (P_J_FF, "inertia_ff", "kg*m^2", "Inertia used for acceleration feed-forward"),
    (P_VFF, "velocity_ff", "", "Velocity feed-forward weight (0..1)"),
    (P_AFF, "acceleration_ff", "", "Acceleration feed-forward weight (0..1)"),
    (P_VMAX, "rate_limit", "rad/s", "Slew and manual rate limit"),
    (P_AMAX, "accel_limit", "rad/s^2", "Slew, stop and manual acceleration limit"),
    (P_CTRL_VMAX, "ctrl_rate_limit", "rad/s", "Limit of the position loop's velocity command"),
    (P_CTRL_AMAX, "ctrl_accel_limit", "rad/s^2", "Limit of the velocity command's rate of change"),
    (P_FERR_MAX, "following_error_limit", "rad", "Watchdog trips beyond this following error"),
    (P_POS_MIN, "position_min", "rad", "Lower axis limit"),
    (P_POS_MAX, "position_max", "rad", "Upper axis limit"),
    (P_I_TRIP, "current_trip", "A", "Watchdog overcurrent threshold"),
    (P_T_MAX, "temperature_max", "degC", "Watchdog over-temperature threshold"),
    (P_RTH, "thermal_resistance", "K/W", "Winding-to-ambient thermal resistance"),
    (P_TAU_TH, "thermal_tau", "s", "Winding thermal time constant"),
    (P_INJ_ENC, "inject_encoder_fault", "bool", "Fault injection: 1 makes the encoder report an error"),
    (P_BRAKE, "brake_torque", "N*m", "Holding brake torque applied while the drive is off"),
    (P_SETTLE_AS, "settle_window", "arcsec", "A slew has arrived when |error| is below this"),
    (P_FRIC_VS, "friction_smoothing", "rad/s", "Coulomb friction rises linearly up to this velocity"),
    (P_INT_ZONE, "integral_zone", "rad", "The position integrator only runs while |error| is below this"),
    (P_FRIC_FF, "friction_ff", "N*m", "Coulomb friction feed-forward of the controller (an estimate)"),
    (P_INJ_FRIC_GROWTH, "inject_friction_growth", "N*m/h", "Fault injection: Coulomb friction rises by this much per hour (a bearing wearing or drying); injected_friction holds what it added"),
    (P_INJ_WINDING, "inject_winding_fault", "", "Fault injection: fraction of the torque constant lost at once (shorted turns): the current steps up by 1/(1 - f)"),
    (P_INJ_RES_GROWTH, "inject_resonance_growth", "N*m/h", "Fault injection: a loosened part rattles at inject_resonance_hz with a torque amplitude growing this much per hour; injected_resonance holds it"),
    (P_INJ_RES_HZ, "inject_resonance_hz", "Hz", "Frequency of the injected rattling (default: the axis's structural resonance)"),
    (P_INJ_GLITCH_RATE, "inject_encoder_glitches", "1/s", "Fault injection: mean rate of encoder glitches (one tick's reading off by inject_encoder_glitch_counts counts, at pseudo-random ticks)"),
    (P_INJ_GLITCH_COUNTS, "inject_encoder_glitch_counts", "count", "Size of one encoder glitch (sign alternates pseudo-randomly)"),
    (P_INJ_HEAT_GROWTH, "inject_heat_growth", "W/h", "Fault injection: extra heat in the winding grows by this much per hour (a temperature runaway); injected_heat holds it"),
]

# Measured quantities, reported in single precision like the real MCU's ADC and sensor
# readings (1e-7 relative, far below their noise); everything else keeps f64/i64.
_MEASURED_GLOBAL = {"power.bus_voltage", "power.supply_power", "power.chopper_power",
                    "power.regen_energy"}
_MEASURED_AXIS = {"error_arcsec", "error_peak_arcsec", "load_error_arcsec", "twist_arcsec",
                  "current", "current_cmd", "torque", "power", "temperature",
                  # the injected degradations are torques and powers like the measured ones
                  "injected_friction", "injected_resonance", "injected_heat"}

STATE_SIZE = STATE_AXIS0 + len(AXES) * AXIS_STRIDE
PARAM_SIZE = PARAM_AXIS0 + len(AXES) * AXIS_STRIDE


def _wire_type(kind: str, measured: bool) -> str:
    if kind == "status":
        return "i64"
    return "f32" if measured else "f64"


def _build_state_slots() -> list[Slot]:
    slots = [Slot(n, i, u, d, kind=k, traced=k == "signal",
                  type=_wire_type(k, n in _MEASURED_GLOBAL))
             for i, n, u, d, k in _GLOBAL_STATE]
    for a, axis in enumerate(AXES):
        base = STATE_AXIS0 + a * AXIS_STRIDE
        slots += [
            Slot(f"axis.{axis}.{n}", base + i, u, d, kind=k, traced=k == "signal",
                 type=_wire_type(k, n in _MEASURED_AXIS))
            for i, n, u, d, k in _AXIS_STATE
        ]
    return slots


def _build_param_slots() -> list[Slot]:
    slots = [Slot(n, i, u, d, v, kind="parameter") for i, n, u, d, v in _GLOBAL_PARAMS]
    for a, axis in enumerate(AXES):
        base = PARAM_AXIS0 + a * AXIS_STRIDE
        defaults = _axis_param_defaults(axis)
        slots += [
            Slot(f"axis.{axis}.{n}", base + i, u, d, defaults[i], kind="parameter")
            for i, n, u, d in _AXIS_PARAMS
        ]
    return slots


STATE_SLOTS: list[Slot] = _build_state_slots()
PARAM_SLOTS: list[Slot] = _build_param_slots()
STATE_INDEX: dict[str, int] = {s.name: s.index for s in STATE_SLOTS}
PARAM_INDEX: dict[str, int] = {s.name: s.index for s in PARAM_SLOTS}


# The range a WRITE may set (ASTCom LIST shows it; a value outside is refused whole).
# Gains and feed-forward weights: from 0 to well above their tuning; rates, accelerations
# and currents: positive and at most a few times the design value; fault injections 0/1.
_FIXED_RANGES: dict[str, tuple[float, float]] = {
    "velocity_ff": (0.0, 1.0), "acceleration_ff": (0.0, 1.0), "kvd": (0.0, 50.0),
    "position_min": (-2 * math.pi, 2 * math.pi), "position_max": (-2 * math.pi, 2 * math.pi),
    "encoder_bits": (8.0, 40.0), "inject_encoder_fault": (0.0, 1.0),
    "safety.inject_heartbeat_miss": (0.0, 1.0), "time.drift_ppm": (-1000.0, 1000.0),
    "traj.late_margin_us": (0.0, 1e6), "traj.replace_min_lead_us": (0.0, 1e6),
    "temperature_max": (0.0, 200.0),
    "power.ambient_temperature": (-60.0, 60.0), "gravity_imbalance": (-1000.0, 1000.0),
    "settle_window": (1e-3, 3600.0), "integral_zone": (0.0, 1.0),
    "friction_smoothing": (1e-9, 1.0), "cogging_periods": (0.0, 1000.0),
    "safety.heartbeat_timeout": (1e-4, 1.0),
    "inject_friction_growth": (-100.0, 100.0), "inject_winding_fault": (0.0, 0.9),
    "inject_resonance_growth": (0.0, 100.0), "inject_resonance_hz": (0.1, 2000.0),
    "inject_encoder_glitches": (0.0, 5000.0), "inject_encoder_glitch_counts": (-1e6, 1e6),
    "inject_heat_growth": (-1000.0, 1000.0), "time.inject_drift_growth": (-1000.0, 1000.0),
}
_SCALED_RANGES: dict[str, tuple[float, float]] = {  # (lowest, highest × default)
    "kp": (0.0, 10.0), "ki": (0.0, 10.0), "kv": (0.0, 10.0), "kvi": (0.0, 10.0),
    "rate_limit": (1e-6, 3.0), "accel_limit": (1e-6, 3.0), "ctrl_rate_limit": (1e-6, 3.0),
    "ctrl_accel_limit": (1e-6, 3.0), "current_limit": (1e-3, 3.0), "current_trip": (1e-3, 3.0),
    "following_error_limit": (1e-6, 10.0),
}


# Parameters that must stay strictly positive (the step divides by them), and those that
# may be zero but never negative.
POSITIVE_PARAMS = frozenset({
    "inertia_motor", "inertia_load", "torque_constant", "current_tau", "thermal_resistance",
    "thermal_tau", "friction_smoothing", "velocity_filter_tau", "rate_limit", "accel_limit",
    "ctrl_rate_limit", "ctrl_accel_limit", "following_error_limit", "current_limit",
    "supply_resistance", "bus_capacitance", "chopper_resistance", "heartbeat_timeout",
})
NONNEGATIVE_PARAMS = frozenset({"stiffness", "damping", "winding_resistance",
                                "viscous_friction", "coulomb_friction", "cogging",
                                "brake_torque", "friction_ff", "integral_zone"})


def param_range(slot: Slot) -> tuple[float, float]:
    """Return the (min, max) a parameter may be written to, in its unit; a parameter the
    step divides by (POSITIVE_PARAMS) never reaches 0: at least 1e-6 × its default."""
    lo, hi = _declared_range(slot)
    if slot.name.rsplit(".", 1)[-1] in POSITIVE_PARAMS and lo <= 0:
        lo = 1e-6 * slot.default
    return lo, hi


def _declared_range(slot: Slot) -> tuple[float, float]:
    short = slot.name.rsplit(".", 1)[-1]
    for key in (slot.name, short):
        if key in _FIXED_RANGES:
            return _FIXED_RANGES[key]
    if short in _SCALED_RANGES:
        lo, factor = _SCALED_RANGES[short]
        return lo, factor * slot.default
    # physical constants of the plant: positive, up to a thousand times the design value
    return 0.0, 1000.0 * max(abs(slot.default), 1.0)


def state_index(axis: int, field: int) -> int:
    """Return the state-array index of a per-axis field (``A_*``) of axis 0 (az) or 1 (el)."""
    return STATE_AXIS0 + axis * AXIS_STRIDE + field


def param_index(axis: int, field: int) -> int:
    """Return the parameter-array index of a per-axis parameter (``P_*``)."""
    return PARAM_AXIS0 + axis * AXIS_STRIDE + field


def default_params():
    """Return a fresh parameter array holding every documented default."""
    import numpy as np

    params = np.zeros(PARAM_SIZE)
    for slot in PARAM_SLOTS:
        params[slot.index] = slot.default
    return params
