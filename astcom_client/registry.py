"""Register a device's variables and functions in a Collection, once, at start-up.

A variable is a getter (and maybe a setter) plus its description; the getter of a
*slot* reads one element or slice of a numpy array that the device's compiled code
updates, so ASTCom reading it costs a field read. Dataclass fields declared with
`astcom_field(...)` are registered recursively by `Collection.register(obj)`.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .exceptions import InvalidValue, UnknownName
from .types import NUMERIC_DTYPES, TypeSpec, parse_type

__all__ = ["Collection", "Function", "Variable", "VariableInfo", "astcom_field"]

KINDS = ("signal", "parameter")
ACCESSES = ("r", "rw")
_NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*$")
_PY_TYPES = {float: "f64", int: "i64", bool: "bool", str: "str", bytes: "bytes"}
_META_KEY = "astcom"


@dataclass(frozen=True)
class VariableInfo:
    """One entry of a listing: what a client learns about a variable or function.

    `min`/`max`: the range a WRITE must respect (numeric variables that declare one;
    None: unbounded on that side), in `unit`.
    """

    name: str
    type: str
    kind: str
    access: str
    unit: str = ""
    doc: str = ""
    min: float | None = None
    max: float | None = None

    def as_dict(self) -> dict[str, Any]:
        """Return the entry as the map sent by LIST (`min`/`max` only when declared)."""
        out = dataclasses.asdict(self)
        for key in ("min", "max"):
            if out[key] is None:
                del out[key]
        return out


@dataclass(eq=False)
class Variable:
    """A registered variable: description plus accessors.

    `trace_column` is its column in the per-tick trace handed to `Endpoint.publish`,
    or None when it is sampled once per block through `get`.
    """

    name: str
    spec: TypeSpec
    kind: str
    access: str
    unit: str
    doc: str
    get: Callable[[], Any]
    set: Callable[[Any], None] | None
    trace_column: int | None = None
    min_value: float | None = None
    max_value: float | None = None

    @property
    def type(self) -> str:
        return self.spec.name

    def check_range(self, value: Any) -> None:
        """Raise InvalidValue when `value` (or an element of it) lies outside [min, max]."""
        if self.min_value is None and self.max_value is None:
            return
        values = np.atleast_1d(np.asarray(value, dtype=float))
        unit = f" {self.unit}" if self.unit else ""
        allowed = (f"{'-∞' if self.min_value is None else f'{self.min_value:g}'}.."
                   f"{'∞' if self.max_value is None else f'{self.max_value:g}'}{unit}")
        if self.min_value is not None and (np.isnan(values) | (values < self.min_value)).any():
            bad = values[np.isnan(values) | (values < self.min_value)][0]
            raise InvalidValue(f"{self.name} = {bad:g}{unit} is below its minimum "
                               f"{self.min_value:g}{unit}; allowed {allowed}")
        if self.max_value is not None and (np.isnan(values) | (values > self.max_value)).any():
            bad = values[np.isnan(values) | (values > self.max_value)][0]
            raise InvalidValue(f"{self.name} = {bad:g}{unit} is above its maximum "
                               f"{self.max_value:g}{unit}; allowed {allowed}")

    @property
    def writable(self) -> bool:
        return "w" in self.access and self.set is not None

    @property
    def readable(self) -> bool:
        return "r" in self.access

    def info(self) -> VariableInfo:
        return VariableInfo(self.name, self.spec.name, self.kind, self.access, self.unit, self.doc,
                            self.min_value, self.max_value)


@dataclass(eq=False)
class Function:
    """A registered function with a typed signature."""

    name: str
    fn: Callable[..., Any]
    args: tuple[tuple[str, TypeSpec], ...]
    returns: TypeSpec | None
    doc: str
    unit: str = ""

    @property
    def signature(self) -> str:
        """Return the type text shown in listings, e.g. `(t_us:i64[],az_rad:f64[])->u32`."""
        ret = self.returns.name if self.returns else "none"
        return "(" + ",".join(f"{n}:{t.name}" for n, t in self.args) + ")->" + ret

    def info(self) -> VariableInfo:
        return VariableInfo(self.name, self.signature, "function", "x", self.unit, self.doc)


@dataclass(frozen=True)
class _FieldMeta:
    type: str | None
    kind: str
    access: str
    unit: str
    doc: str
    traced: bool


def astcom_field(default: Any = dataclasses.MISSING, *, type: str | None = None,  # noqa: A002
                 kind: str = "signal", access: str = "r", unit: str = "", doc: str = "",
                 traced: bool = False, default_factory: Any = dataclasses.MISSING) -> Any:
    """Declare a dataclass field that `Collection.register` publishes.

    The type is inferred from the default when omitted (float → f64, int → i64, ...).
    A field whose value is itself a dataclass is registered recursively under its name.
    """
    meta = {_META_KEY: _FieldMeta(type, kind, access, unit, doc, traced)}
    if default_factory is not dataclasses.MISSING:
        return field(default_factory=default_factory, metadata=meta)
    return field(default=default, metadata=meta)


class Collection:
    """Hold every variable and function a device publishes, by dotted name."""

    def __init__(self) -> None:
        self._entries: dict[str, Variable | Function] = {}
        self._trace_width = 0
        self._frozen = False

    # -- registration -------------------------------------------------------------------
    def add_variable(self, name: str, type: str, *, kind: str = "signal",  # noqa: A002
                     access: str = "r", unit: str = "", doc: str = "",
                     get: Callable[[], Any], set: Callable[[Any], None] | None = None,  # noqa: A002
                     traced: bool = False, min_value: float | None = None,
                     max_value: float | None = None) -> Variable:
        """Register a variable read through `get` (and written through `set`).

        `min_value`/`max_value` bound what a WRITE may set (numeric types only; LIST
        shows them as `min`/`max`): a value outside is refused (422), nothing applied.
        """
        spec = parse_type(type)
        self._check_new(name)
        if kind not in KINDS:
            raise ValueError(f"{name}: kind must be one of {KINDS}, got {kind!r}")
        if access not in ACCESSES:
            raise ValueError(f"{name}: access must be one of {ACCESSES}, got {access!r}")
        if "w" in access and set is None:
            raise ValueError(f"{name}: access {access!r} needs a setter")
        if not callable(get):
            raise TypeError(f"{name}: get must be callable")
        _check_bounds(name, spec, min_value, max_value)
        column = None
        if traced:
            if not spec.is_numeric_scalar:
                raise ValueError(f"{name}: only numeric scalars can be traced, not {spec.name}")
            column = self._trace_width
            self._trace_width += 1
        var = Variable(name, spec, kind, access, unit, doc, get, set, column,
                       None if min_value is None else float(min_value),
                       None if max_value is None else float(max_value))
        self._entries[name] = var
        return var

    def add_slot(self, name: str, array: np.ndarray, index: int | slice | tuple, *,
                 type: str, kind: str = "signal", access: str = "r",  # noqa: A002
                 unit: str = "", doc: str = "", traced: bool = False,
                 min_value: float | None = None, max_value: float | None = None) -> Variable:
        """Register `array[index]` as a variable; the device keeps updating the array."""
        if not isinstance(array, np.ndarray):
            raise TypeError(f"{name}: add_slot needs a numpy array, got {type(array).__name__}")
        spec = parse_type(type)
        current = array[index]
        if spec.shape is None and np.ndim(current) != 0:
            raise ValueError(f"{name}: index {index!r} selects shape {np.shape(current)}, "
                             f"but type {spec.name} is a scalar")
        if spec.shape is not None and np.shape(current) != spec.shape:
            raise ValueError(f"{name}: index {index!r} selects shape {np.shape(current)}, "
                             f"but type {spec.name} needs {spec.shape}")
        if spec.shape is None:
            def get() -> Any:
                return array[index]
        else:
            def get() -> Any:
                return array[index].copy()

        def put(value: Any) -> None:
            array[index] = value

        return self.add_variable(name, spec.name, kind=kind, access=access, unit=unit, doc=doc,
                                 get=get, set=put if "w" in access else None, traced=traced,
                                 min_value=min_value, max_value=max_value)

    def add_function(self, name: str, fn: Callable[..., Any], *,
                     args: Sequence[tuple[str, str]] = (), returns: str | None = None,
                     doc: str = "", unit: str = "") -> Function:
        """Register a function callable by INVOKE with typed arguments."""
        self._check_new(name)
        if not callable(fn):
            raise TypeError(f"{name}: fn must be callable")
        parsed = tuple((arg, parse_type(t)) for arg, t in args)
        func = Function(name, fn, parsed, parse_type(returns) if returns else None, doc, unit)
        self._entries[name] = func
        return func

    def register(self, obj: Any, prefix: str = "") -> list[Variable]:
        """Register every `astcom_field` of dataclass `obj`, recursing into nested dataclasses."""
        if not dataclasses.is_dataclass(obj) or isinstance(obj, type):
            raise TypeError(f"register needs a dataclass instance, got {type(obj).__name__}")
        added: list[Variable] = []
        for f in dataclasses.fields(obj):
            meta = f.metadata.get(_META_KEY)
            if meta is None:
                continue
            name = f"{prefix}.{f.name}" if prefix else f.name
            value = getattr(obj, f.name)
            if dataclasses.is_dataclass(value) and not isinstance(value, type):
                added += self.register(value, name)
                continue
            added.append(self._add_field(obj, f.name, name, meta, value))
        return added

    def _add_field(self, obj: Any, attr: str, name: str, meta: _FieldMeta, value: Any) -> Variable:
        type_name = meta.type or _PY_TYPES.get(type(value))
        if type_name is None:
            raise ValueError(f"{name}: cannot infer an ASTCom type from {type(value).__name__}; "
                             "give astcom_field(type=...)")
        spec = parse_type(type_name)

        def get() -> Any:
            return getattr(obj, attr)

        def put(new: Any) -> None:
            setattr(obj, attr, new if spec.shape is None else np.array(new))

        return self.add_variable(name, type_name, kind=meta.kind, access=meta.access,
                                 unit=meta.unit, doc=meta.doc, get=get,
                                 set=put if "w" in meta.access else None, traced=meta.traced)

    def _check_new(self, name: str) -> None:
        if self._frozen:
            raise RuntimeError(f"cannot register {name!r}: the collection is frozen once an "
                               "Endpoint serves it (register everything at start-up)")
        if not isinstance(name, str) or not _NAME_RE.match(name):
            raise ValueError(f"invalid name {name!r}: expected dotted identifiers such as "
                             "'axis.az.position'")
        if name in self._entries:
            raise ValueError(f"{name!r} is already registered")

    def freeze(self) -> None:
        """Refuse further registration (called by the Endpoint)."""
        self._frozen = True

    # -- lookup ---------------------------------------------------------------------------
    @property
    def trace_width(self) -> int:
        """Return the number of columns of the per-tick trace (one per traced variable)."""
        return self._trace_width

    def __getitem__(self, name: str) -> Variable | Function:
        return self._entries[name]

    def __contains__(self, name: object) -> bool:
        return name in self._entries

    def __iter__(self) -> Iterator[Variable | Function]:
        return iter(self._entries.values())

    def __len__(self) -> int:
        return len(self._entries)

    def variable(self, name: str) -> Variable:
        """Return the variable `name`; raise KeyError (UnknownName) otherwise."""
        entry = self._entries.get(name)
        if isinstance(entry, Function):
            raise UnknownName(f"{name!r} is a function, not a variable: call it with INVOKE",
                              name=name)
        if not isinstance(entry, Variable):
            raise UnknownName(f"no variable named {name!r}"
                              f"{_hint(name, self._entries, Variable)}", name=name)
        return entry

    def function(self, name: str) -> Function:
        """Return the function `name`; raise KeyError (UnknownName) otherwise."""
        entry = self._entries.get(name)
        if isinstance(entry, Variable):
            raise UnknownName(f"{name!r} is a variable, not a function: READ, WRITE or stream "
                              "it", name=name)
        if not isinstance(entry, Function):
            raise UnknownName(f"no function named {name!r}"
                              f"{_hint(name, self._entries, Function)}", name=name)
        return entry

    def infos(self, prefix: str = "") -> list[VariableInfo]:
        """Return the listing of every entry whose name starts with `prefix`."""
        return [e.info() for e in self._entries.values() if e.name.startswith(prefix)]


def _check_bounds(name: str, spec: TypeSpec, lo: float | None, hi: float | None) -> None:
    if lo is None and hi is None:
        return
    if spec.base not in NUMERIC_DTYPES or spec.base == "bool":
        raise ValueError(f"{name}: only numeric variables take min/max, not {spec.name}")
    for label, bound in (("min_value", lo), ("max_value", hi)):
        if bound is not None and not np.isfinite(bound):
            raise ValueError(f"{name}: {label} must be a finite number, got {bound!r}")
    if lo is not None and hi is not None and lo > hi:
        raise ValueError(f"{name}: min_value {lo} is above max_value {hi}")


def _hint(name: str, entries: dict[str, Any], kind: type) -> str:
    """Suggest up to three names of the same kind (a variable for a variable)."""
    import difflib

    close = difflib.get_close_matches(
        name, [n for n, e in entries.items() if isinstance(e, kind)], n=3)
    return f"; did you mean {', '.join(close)}?" if close else ""
