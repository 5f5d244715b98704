"""A Collection registers slots, closures, nested dataclasses and typed functions once."""

from dataclasses import dataclass

import numpy as np
import pytest

from astcom_client import Collection, UnknownName, astcom_field


def test_a_slot_reads_the_live_array_element() -> None:
    state = np.zeros(4)
    coll = Collection()
    var = coll.add_slot("axis.az.position", state, 2, type="f64", unit="rad", doc="Azimuth")
    state[2] = 1.25
    assert var.get() == 1.25
    assert var.info().as_dict() == {"name": "axis.az.position", "type": "f64", "kind": "signal",
                                     "access": "r", "unit": "rad", "doc": "Azimuth"}


def test_a_writable_array_slot_writes_through_to_the_device_array() -> None:
    arr = np.zeros(5)
    coll = Collection()
    var = coll.add_slot("geom.ia", arr, slice(1, 4), type="f64[3]", kind="parameter", access="rw")
    assert var.set is not None
    var.set(np.array([1.0, 2.0, 3.0]))
    assert arr.tolist() == [0.0, 1.0, 2.0, 3.0, 0.0]
    snapshot = var.get()
    arr[1] = 9.0
    assert snapshot[0] == 1.0  # reads are copies, never views the device keeps changing


def test_slot_shape_must_match_the_declared_type() -> None:
    coll = Collection()
    with pytest.raises(ValueError, match="shape"):
        coll.add_slot("x", np.zeros(4), slice(0, 2), type="f64[3]")
    with pytest.raises(ValueError, match="scalar"):
        coll.add_slot("y", np.zeros(4), slice(0, 2), type="f64")


def test_traced_variables_get_consecutive_trace_columns() -> None:
    coll = Collection()
    state = np.zeros(3)
    a = coll.add_slot("a", state, 0, type="f64", traced=True)
    coll.add_slot("b", state, 1, type="f64")
    c = coll.add_slot("c", state, 2, type="f64", traced=True)
    assert (a.trace_column, c.trace_column, coll.trace_width) == (0, 1, 2)
    with pytest.raises(ValueError, match="traced"):
        coll.add_variable("s", "str", get=lambda: "", traced=True)


@dataclass
class Inner:
    current_a: float = astcom_field(1.0, kind="parameter", access="rw", unit="A", doc="Limit")


@dataclass
class Outer:
    voltage_v: float = astcom_field(24.0, unit="V", doc="Bus voltage")
    count: int = astcom_field(3)
    inner: Inner = astcom_field(default_factory=Inner)
    private: str = "hidden"


def test_register_walks_nested_dataclasses_and_skips_plain_fields() -> None:
    coll = Collection()
    obj = Outer()
    coll.register(obj, prefix="power")
    assert [e.name for e in coll] == ["power.voltage_v", "power.count", "power.inner.current_a"]
    assert coll.variable("power.count").type == "i64"
    var = coll.variable("power.inner.current_a")
    assert var.set is not None
    var.set(2.0)
    assert obj.inner.current_a == 2.0
    obj.voltage_v = 12.0
    assert coll.variable("power.voltage_v").get() == 12.0


def test_functions_list_their_signature_as_their_type() -> None:
    coll = Collection()
    coll.add_function("traj.push", lambda t, a: len(t), args=[("t_us", "i64[]"), ("az_rad", "f64[]")],
                      returns="u32", doc="Append points")
    info = coll.function("traj.push").info()
    assert (info.type, info.kind, info.access) == ("(t_us:i64[],az_rad:f64[])->u32", "function", "x")


@pytest.mark.parametrize("name", ["", "1abc", "a..b", "a.b-c", "a b"])
def test_invalid_names_are_refused(name: str) -> None:
    with pytest.raises(ValueError, match="invalid name"):
        Collection().add_variable(name, "f64", get=lambda: 0.0)


def test_duplicate_names_and_late_registration_are_refused() -> None:
    coll = Collection()
    coll.add_variable("x", "f64", get=lambda: 0.0)
    with pytest.raises(ValueError, match="already"):
        coll.add_variable("x", "f64", get=lambda: 0.0)
    coll.freeze()
    with pytest.raises(RuntimeError, match="frozen"):
        coll.add_variable("y", "f64", get=lambda: 0.0)


def test_unknown_names_suggest_close_matches() -> None:
    coll = Collection()
    coll.add_variable("axis.az.position", "f64", get=lambda: 0.0)
    with pytest.raises(UnknownName, match="did you mean axis.az.position") as info:
        coll.variable("axis.az.positon")
    assert isinstance(info.value, KeyError)


def test_rw_access_needs_a_setter() -> None:
    with pytest.raises(ValueError, match="setter"):
        Collection().add_variable("x", "f64", access="rw", get=lambda: 0.0)
