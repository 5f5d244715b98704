"""Publish every signal, parameter and command of the mount in an ASTCom Collection.

Names are dotted (``axis.az.position``, ``traj.push``), units travel with them.
Signals read slots of the state array (traced: streamable per tick); parameters
are slots of the parameter array, written between two ticks and used by the
very next tick; functions wrap `MountModel` commands with degree/radian
conversions at the user interface.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from astcom_client import Collection
from mount_emulator import layout as L
from mount_emulator.states import fault_text

if TYPE_CHECKING:
    from mount_emulator.emulator import MountEmulator

__all__ = ["POSITIVE_PARAMS", "build_collection"]

POSITIVE_PARAMS = L.POSITIVE_PARAMS  # the layout knows them: param_range keeps them > 0
NONNEGATIVE_PARAMS = L.NONNEGATIVE_PARAMS


def _param_setter(params: np.ndarray, slot: L.Slot,
                  on_write: Callable[[str, float, float], None] | None = None
                  ) -> Callable[[float], None]:
    short = slot.name.rsplit(".", 1)[-1]

    def put(value: float) -> None:
        v = float(value)
        if not math.isfinite(v):
            raise ValueError(f"{slot.name} must be finite, got {value!r}")
        if short in POSITIVE_PARAMS and v <= 0:
            raise ValueError(f"{slot.name} must be > 0 {slot.unit}, got {v}")
        if short in NONNEGATIVE_PARAMS and v < 0:
            raise ValueError(f"{slot.name} must be >= 0 {slot.unit}, got {v}")
        if short == "encoder_bits" and not 8 <= v <= 40:
            raise ValueError(f"{slot.name} must be between 8 and 40 bits, got {v}")
        old = float(params[slot.index])
        params[slot.index] = v
        if on_write is not None and old != v:
            on_write(slot.name, old, v)

    return put


def build_collection(emu: MountEmulator) -> tuple[Collection, dict[int, int]]:
    """Return the Collection of the emulator and the map trace column → state index."""
    model = emu.model
    state, params = model.state, model.params
    coll = Collection()
    column_to_state: dict[int, int] = {}
    for slot in L.STATE_SLOTS:
        if slot.kind == "status":
            var = coll.add_variable(slot.name, "i64", unit=slot.unit, doc=slot.doc,
                                    get=lambda i=slot.index: int(state[i]), traced=True)
        else:
            # f32 slots stay float64 in the state array; the endpoint rounds on read/stream
            var = coll.add_slot(slot.name, state, slot.index, type=slot.type, unit=slot.unit,
                                doc=slot.doc, traced=True)
        column_to_state[var.trace_column] = slot.index
    for slot in L.PARAM_SLOTS:
        lo, hi = L.param_range(slot)
        coll.add_variable(slot.name, "f64", kind="parameter", access="rw", unit=slot.unit,
                          doc=f"{slot.doc} (default {slot.default:g})",
                          get=lambda i=slot.index: float(params[i]),
                          set=_param_setter(params, slot, emu.param_written),
                          min_value=lo, max_value=hi)
    _add_text_signals(coll, emu)
    _add_loop_health(coll, emu)
    _add_functions(coll, emu)
    _add_log(coll, emu)
    return coll, column_to_state


# Commands that change what the mount does are logged (kind "command"); reads and the
# frequent trajectory pushes are not.
LOGGED_COMMANDS = {"mount.power_on", "mount.power_off", "mount.stop", "mount.slew",
                   "axis.az.move", "axis.el.move", "traj.init", "traj.start", "traj.reset",
                   "time.set_utc", "safety.reset", "fault.clear_injections"}


def _add_log(coll: Collection, emu: MountEmulator) -> None:
    """`log.*`: the emulator's structured event log (astcom_client.events)."""
    coll.add_variable("log.last_seq", "u64", doc="Sequence number of the newest logged event",
                      get=lambda: emu.log.last_seq)
    coll.add_function("log.since", emu.log.since_json, args=[("seq", "u64")], returns="str",
                      doc="Events after sequence number seq, oldest first, as a JSON list of "
                          "{seq, t_us, utc, source, level, kind, message, fields}")
    for name in LOGGED_COMMANDS:
        func = coll.function(name)
        func.fn = _logged(emu, name, func.fn)


def _logged(emu: MountEmulator, name: str, fn: Callable) -> Callable:
    def call(*args):
        result = fn(*args)
        shown = ", ".join(f"{a:g}" if isinstance(a, float) else str(a) for a in args)
        emu.log_event("info", "fault_reset" if name == "safety.reset" else "command",
                      f"{name}({shown})", command=name, args=[_plain(a) for a in args])
        return result

    return call


def _plain(value):
    return value.item() if hasattr(value, "item") else value


def _add_loop_health(coll: Collection, emu: MountEmulator) -> None:
    """`loop.*`: how well the device loop keeps its time (mount_emulator/loop_health.py)."""
    for name, type_, unit, doc in (
            ("overruns", "u64", "", "Wake-ups that found more than one block of ticks due "
             "(the loop fell behind wall time; real time only)"),
            ("late_ticks", "u64", "", "Ticks computed while the loop was behind by more than "
             "one block"),
            ("blocks", "u64", "", "Blocks of ticks computed since start"),
            ("worst_block_us", "f64", "us", "Longest wall time of computing one block"),
            ("last_block_us", "f64", "us", "Wall time of computing the last block"),
            ("worst_lag_us", "f64", "us", "Largest lag of mount time behind its wall-clock due "
             "time at a wake-up (real time only)")):
        coll.add_variable(f"loop.{name}", type_, unit=unit, doc=doc,
                          get=lambda n=name: getattr(emu.health, n))
    coll.add_function("loop.reset_health", emu.health_reset,
                      doc="Zero the loop.* counters (e.g. after start-up or a load test)")


def _add_text_signals(coll: Collection, emu: MountEmulator) -> None:
    model = emu.model
    coll.add_variable("mount.state_name", "str", doc="Mount state as text",
                      get=lambda: model.mount_state.name)
    for a, axis in enumerate(L.AXES):
        coll.add_variable(f"axis.{axis}.state_name", "str", doc=f"{axis} axis state as text",
                          get=lambda a=a: model.axis_state(a).name)
        coll.add_variable(f"axis.{axis}.fault_text", "str", doc=f"{axis} latched faults as text",
                          get=lambda a=a: fault_text(int(model.axis_slot(a, L.A_FAULTS))))
    coll.add_variable("traj.free_points", "i64", doc="Free space in the trajectory buffer (points)",
                      get=model.traj_free)
    coll.add_variable("traj.count", "i64", doc="Points in the trajectory buffer",
                      get=model.traj_count)
    coll.add_variable("traj.capacity", "i64", doc="Trajectory buffer capacity (points)",
                      get=lambda: model.traj_capacity)
    coll.add_variable("guide.seeing_arcsec", "f64", kind="parameter", access="rw", unit="arcsec",
                      doc="1-sigma seeing noise of the guide camera per axis",
                      get=lambda: emu.camera.seeing_arcsec, set=emu.set_seeing)
    coll.add_variable("guide.dx_arcsec", "f64", unit="arcsec",
                      doc="Last guide measurement: star minus optical axis, azimuth x cos(el)",
                      get=lambda: emu.last_guide[0])
    coll.add_variable("guide.dy_arcsec", "f64", unit="arcsec",
                      doc="Last guide measurement: star minus optical axis, elevation",
                      get=lambda: emu.last_guide[1])
    coll.add_variable("truth.geometry_arcsec", "f64[7]", unit="arcsec",
                      doc="The hidden true geometry, TPOINT terms IA, IE, AN, AW, NPAE, CA, TF "
                          "(observed - encoder = delta): for truth devices beside the emulator "
                          "(the guide camera simulator), never for the VSS",
                      get=lambda: np.array([getattr(emu.camera.geometry, k) for k in
                                            ("ia", "ie", "an", "aw", "npae", "ca", "tf")]))
    coll.add_variable("sim.speed", "f64", unit="x",
                      doc="Simulated-time speed factor (0 = as fast as possible)",
                      get=lambda: emu.speed)
    coll.add_variable("time.utc_iso", "str", doc="Mount clock as ISO-8601 UTC text",
                      get=emu.mount_time_iso)


def _add_functions(coll: Collection, emu: MountEmulator) -> None:
    m = emu.model
    coll.add_function("mount.power_on", m.power_on, doc="Close the loops on both axes, holding")
    coll.add_function("mount.power_off", m.power_off, doc="Cut both drives, brakes on")
    coll.add_function("mount.stop", m.stop, doc="Ramp both axes to rest")
    coll.add_function("mount.slew", lambda az, el: m.slew(math.radians(az), math.radians(el)),
                      args=[("az_deg", "f64"), ("el_deg", "f64")],
                      doc="Slew both axes to (az, el) encoder degrees under the rate/accel limits")
    for a, axis in enumerate(L.AXES):
        coll.add_function(f"axis.{axis}.move", lambda r, a=a: m.move(a, math.radians(r)),
                          args=[("rate_deg_s", "f64")],
                          doc=f"Move the {axis} axis at a constant rate (0 holds still)")
    coll.add_function("traj.init", m.traj_init, doc="Empty the trajectory buffer, zero its counters")
    coll.add_function("traj.start", m.traj_start, doc="Start following the trajectory buffer")
    coll.add_function("traj.reset", m.traj_reset,
                      doc="Abort the trajectory: ramp to rest, empty the buffer")
    coll.add_function("traj.free", m.traj_free, returns="u32",
                      doc="Return the free space of the trajectory buffer (points)")
    coll.add_function("traj.push", m.traj_push,
                      args=[("t_us", "i64[]"), ("az_rad", "f64[]"), ("el_rad", "f64[]")],
                      returns="u32",
                      doc="Append points (mount time µs, encoder rad); returns the accepted count")
    coll.add_function("traj.push_rates", m.traj_push,
                      args=[("t_us", "i64[]"), ("az_rad", "f64[]"), ("el_rad", "f64[]"),
                            ("az_rate_rad_s", "f64[]"), ("el_rate_rad_s", "f64[]")],
                      returns="u32", doc="Append points with their rates; returns the accepted count")
    coll.add_function("traj.replace_from", m.traj_replace_from,
                      args=[("from_us", "i64"), ("t_us", "i64[]"), ("az_rad", "f64[]"),
                            ("el_rad", "f64[]"), ("az_rate_rad_s", "f64[]"),
                            ("el_rate_rad_s", "f64[]")],
                      returns="u32",
                      doc="Atomically drop every buffered point at or after from_us (mount µs) "
                          "and append these points (at or after from_us, with rates); refused "
                          "when from_us is less than traj.replace_min_lead_us ahead of the "
                          "clock; returns the accepted count")
    coll.add_function("time.set_utc", m.set_utc, args=[("utc_second", "i64")],
                      doc="Arm a UTC second (since 1970): the mount clock takes it at the next PPS edge")
    coll.add_function("time.now_us", lambda: m.mount_time_us, returns="i64",
                      doc="Return the mount clock (µs since 1970 UTC)")
    coll.add_function("safety.reset", m.safety_reset,
                      doc="Clear latched faults; faulted axes go to OFF")
    coll.add_function("fault.clear_injections", m.clear_injections,
                      doc="End every fault injection: inject_* parameters to their defaults, "
                          "grown friction, rattling, heat and clock drift back to zero")
    coll.add_function("guide.measure", emu.guide_measure,
                      args=[("star_az_deg", "f64"), ("star_el_deg", "f64")], returns="f64[2]",
                      doc="Offset (arcsec) of a star at observed (az, el) from the optical axis, "
                          "from the current encoders, the hidden geometry and seeing")

