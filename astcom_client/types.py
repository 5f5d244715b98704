"""Parse ASTCom type names and check/coerce values against them.

Type grammar (the same text appears on the wire and in listings)::

    type    := scalar | scalar "[" dims "]" | scalar "[]" | struct
    scalar  := bool | i8 | i16 | i32 | i64 | u8 | u16 | u32 | u64 | f32 | f64 | str | bytes
    dims    := N ("," N)*              fixed shape, e.g. f64[3], f64[3,3]
    struct  := "{" name ":" type ("," name ":" type)* "}"   e.g. {lat_deg:f64,lon_deg:f64}

`f64[]` is a one-dimensional array of any length (function arguments such as a
trajectory). Arrays hold numeric or bool elements only.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any

import numpy as np

from .exceptions import InvalidValue

__all__ = ["NUMERIC_DTYPES", "SCALAR_NAMES", "TypeSpec", "parse_type"]

NUMERIC_DTYPES: dict[str, np.dtype] = {
    "bool": np.dtype("?"),
    "i8": np.dtype("<i1"),
    "i16": np.dtype("<i2"),
    "i32": np.dtype("<i4"),
    "i64": np.dtype("<i8"),
    "u8": np.dtype("<u1"),
    "u16": np.dtype("<u2"),
    "u32": np.dtype("<u4"),
    "u64": np.dtype("<u8"),
    "f32": np.dtype("<f4"),
    "f64": np.dtype("<f8"),
}
SCALAR_NAMES = (*NUMERIC_DTYPES, "str", "bytes")
VARIABLE_LENGTH = -1
_MAX_DIMS = 4
_ARRAY_RE = re.compile(r"^([a-z0-9]+)\[([0-9, ]*)\]$")
_NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


@dataclass(frozen=True)
class TypeSpec:
    """A parsed ASTCom type: a scalar, a fixed or variable array, or a struct."""

    base: str
    shape: tuple[int, ...] | None = None
    fields: tuple[tuple[str, TypeSpec], ...] = ()

    @property
    def name(self) -> str:
        """Return the canonical type text (`f64[3]`, `{a:f64,b:str}`)."""
        if self.base == "struct":
            return "{" + ",".join(f"{n}:{t.name}" for n, t in self.fields) + "}"
        if self.shape is None:
            return self.base
        if self.shape == (VARIABLE_LENGTH,):
            return f"{self.base}[]"
        return f"{self.base}[{','.join(str(d) for d in self.shape)}]"

    def __str__(self) -> str:
        return self.name

    @property
    def dtype(self) -> np.dtype | None:
        """Return the numpy dtype of a numeric scalar/array element, else None."""
        return NUMERIC_DTYPES.get(self.base)

    @property
    def is_numeric_scalar(self) -> bool:
        return self.shape is None and self.base in NUMERIC_DTYPES

    @property
    def is_fixed_array(self) -> bool:
        return self.shape is not None and VARIABLE_LENGTH not in self.shape

    @property
    def n_columns(self) -> int:
        """Return how many stream columns a value takes (0 when it cannot be streamed)."""
        if self.is_numeric_scalar:
            return 1
        if self.is_fixed_array:
            return math.prod(self.shape or ())
        return 0

    def coerce(self, value: Any, *, where: str = "value") -> Any:
        """Return `value` converted to this type; raise InvalidValue saying what was expected."""
        if self.base == "struct":
            return self._coerce_struct(value, where)
        if self.shape is not None:
            return self._coerce_array(value, where)
        return _coerce_scalar(self.base, value, where)

    def to_wire(self, value: Any) -> Any:
        """Return a device-side value in the form the codec sends (python scalars, arrays)."""
        if self.shape is None and self.base in NUMERIC_DTYPES:
            if self.base == "bool":
                return bool(value)
            if self.base == "f32":
                # a device may back an f32 by float64 state: send what a stream packs
                return float(np.float32(value))
            if self.base[0] == "f":
                return float(value)
            return int(value)
        if self.shape is not None:
            return np.asarray(value, dtype=self.dtype)
        if self.base == "struct":
            return {n: t.to_wire(value[n]) for n, t in self.fields}
        return value

    def _coerce_struct(self, value: Any, where: str) -> dict[str, Any]:
        if not isinstance(value, dict):
            raise InvalidValue(f"{where}: expected a map for {self.name}, got {type(value).__name__}")
        names = [n for n, _ in self.fields]
        if set(value) != set(names):
            raise InvalidValue(f"{where}: expected fields {names}, got {sorted(map(str, value))}")
        return {n: t.coerce(value[n], where=f"{where}.{n}") for n, t in self.fields}

    def _coerce_array(self, value: Any, where: str) -> np.ndarray:
        dtype = self.dtype
        assert dtype is not None and self.shape is not None
        if isinstance(value, str | bytes | dict) or np.isscalar(value):
            raise InvalidValue(f"{where}: expected an array {self.name}, got {type(value).__name__}")
        if self.base != "bool" and not isinstance(value, np.ndarray) and _holds_bool(value):
            # a bool is not a number: refused as an element as it is as a scalar
            raise InvalidValue(f"{where}: expected {self.base} elements, got a bool element")
        try:
            arr = np.asarray(value)
        except (ValueError, TypeError) as exc:
            raise InvalidValue(f"{where}: expected an array {self.name}: {exc}") from None
        if self.shape == (VARIABLE_LENGTH,):
            if arr.ndim != 1:
                raise InvalidValue(f"{where}: expected a 1-D array {self.name}, got shape {arr.shape}")
        elif arr.shape != self.shape:
            raise InvalidValue(f"{where}: expected shape {self.shape} for {self.name}, got {arr.shape}")
        return _cast_array(arr, self.base, dtype, where)


def _holds_bool(value: Any) -> bool:
    """Return True when a (nested) list or tuple holds a bool anywhere."""
    for item in value:
        if type(item) is bool or (isinstance(item, list | tuple) and _holds_bool(item)):
            return True
    return False


def _cast_array(arr: np.ndarray, base: str, dtype: np.dtype, where: str) -> np.ndarray:
    if arr.size == 0:
        return np.zeros(arr.shape, dtype=dtype)
    kind = arr.dtype.kind
    if kind not in "biuf" or (kind == "b" and base != "bool"):
        raise InvalidValue(f"{where}: expected {base} elements, got {arr.dtype} elements")
    if base == "bool":
        if kind != "b" and not np.all((arr == 0) | (arr == 1)):
            raise InvalidValue(f"{where}: expected bool elements (true/false or 0/1)")
        return arr.astype(dtype)
    if dtype.kind in "iu":
        if kind == "f" and (not np.all(np.isfinite(arr)) or not np.all(arr == np.round(arr))):
            raise InvalidValue(f"{where}: expected integer elements for {base}, got fractions")
        info = np.iinfo(dtype)
        if kind != "b" and (arr.min() < info.min or arr.max() > info.max):
            raise InvalidValue(f"{where}: elements out of range for {base} ({info.min}..{info.max})")
        return arr.astype(dtype)
    out = arr.astype(dtype)
    if dtype == np.float32 and np.any(np.isinf(out) & np.isfinite(arr)):
        raise InvalidValue(f"{where}: elements out of range for f32")
    return out


def _coerce_scalar(base: str, value: Any, where: str) -> Any:
    if base == "str":
        if not isinstance(value, str):
            raise InvalidValue(f"{where}: expected str, got {type(value).__name__}")
        return value
    if base == "bytes":
        if not isinstance(value, bytes | bytearray | memoryview):
            raise InvalidValue(f"{where}: expected bytes, got {type(value).__name__}")
        return bytes(value)
    if isinstance(value, np.ndarray) and value.ndim == 0:
        value = value.item()
    if isinstance(value, np.generic):
        value = value.item()
    if base == "bool":
        if isinstance(value, bool):
            return value
        if isinstance(value, int) and value in (0, 1):
            return bool(value)
        raise InvalidValue(f"{where}: expected bool (true/false), got {value!r}")
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InvalidValue(f"{where}: expected {base}, got {type(value).__name__} {value!r}")
    dtype = NUMERIC_DTYPES[base]
    if dtype.kind == "f":
        out = float(value)
        if base == "f32" and math.isfinite(out) and abs(out) > float(np.finfo(np.float32).max):
            raise InvalidValue(f"{where}: {value!r} out of range for f32")
        return out
    if isinstance(value, float):
        if not math.isfinite(value) or value != int(value):
            raise InvalidValue(f"{where}: expected an integer for {base}, got {value!r}")
        value = int(value)
    info = np.iinfo(dtype)
    if not info.min <= value <= info.max:
        raise InvalidValue(f"{where}: {value} out of range for {base} ({info.min}..{info.max})")
    return value


def parse_type(text: str | TypeSpec) -> TypeSpec:
    """Parse a type name such as `f64`, `u8[3]`, `f64[]` or `{a:f64,b:str}`; raise ValueError."""
    if isinstance(text, TypeSpec):
        return text
    if not isinstance(text, str):
        raise InvalidValue(f"type must be a string such as 'f64' or 'f64[3]', got {text!r}")
    spec, rest = _parse(text.replace(" ", ""), 0)
    if rest:
        raise InvalidValue(f"unexpected text {rest!r} after type in {text!r}")
    return spec


def _parse(text: str, depth: int) -> tuple[TypeSpec, str]:
    if depth > 8:
        raise InvalidValue("struct types nest deeper than 8 levels")
    if text.startswith("{"):
        return _parse_struct(text[1:], depth)
    end, in_brackets = len(text), False
    for pos, char in enumerate(text):
        in_brackets = (in_brackets or char == "[") and char != "]"
        if char in ",}" and not in_brackets:
            end = pos
            break
    token, rest = text[:end], text[end:]
    match = _ARRAY_RE.match(token)
    if match:
        base, dims = match.groups()
        if base not in NUMERIC_DTYPES:
            raise InvalidValue(f"arrays hold numeric or bool elements, not {base!r} (in {token!r})")
        if dims == "":
            return TypeSpec(base, (VARIABLE_LENGTH,)), rest
        shape = tuple(int(d) for d in dims.split(","))
        if not shape or len(shape) > _MAX_DIMS or min(shape) < 1:
            raise InvalidValue(f"array dimensions must be 1..{_MAX_DIMS} positive sizes, got {token!r}")
        return TypeSpec(base, shape), rest
    if token not in SCALAR_NAMES:
        raise InvalidValue(f"unknown type {token!r}; expected one of {' '.join(SCALAR_NAMES)}, "
                           "an array such as f64[3] or f64[], or a struct {name:type,...}")
    return TypeSpec(token), rest


def _parse_struct(text: str, depth: int) -> tuple[TypeSpec, str]:
    fields: list[tuple[str, TypeSpec]] = []
    while True:
        name, sep, text = text.partition(":")
        if not sep or not _NAME_RE.match(name):
            raise InvalidValue(f"expected 'name:type' in struct type, got {name!r}")
        if any(n == name for n, _ in fields):
            raise InvalidValue(f"duplicate struct field {name!r}")
        spec, text = _parse(text, depth + 1)
        fields.append((name, spec))
        if text.startswith(","):
            text = text[1:]
            continue
        if text.startswith("}"):
            return TypeSpec("struct", None, tuple(fields)), text[1:]
        raise InvalidValue("struct type is missing its closing '}'")
