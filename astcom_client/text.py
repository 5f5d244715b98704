"""Convert between ASTCom values and text: command-line arguments, tables, JSON, CSV."""

from __future__ import annotations

import base64
import json
from typing import Any

import numpy as np

from .codec import TimestampUs
from .exceptions import InvalidValue
from .types import TypeSpec, parse_type

__all__ = ["parse_signature", "to_jsonable", "value_from_text", "value_to_text"]

_TRUE = {"true", "1", "yes", "on"}
_FALSE = {"false", "0", "no", "off"}


def value_from_text(spec: TypeSpec | str, text: str, *, where: str = "value") -> Any:
    """Return the value of type `spec` written as `text`; raise InvalidValue with an example.

    Scalars are written plainly (``1.5``, ``-3``, ``true``); arrays and structs as JSON
    (``[1, 2, 3]``, ``{"lat_deg": 45}``); bytes as hex (``0a1b``).
    """
    spec = parse_type(spec)
    if spec.base == "str" and spec.shape is None:
        return text
    if spec.base == "bytes" and spec.shape is None:
        try:
            return bytes.fromhex(text)
        except ValueError:
            raise InvalidValue(f"{where}: expected hex bytes such as 0a1b, got {text!r}") from None
    if spec.base == "bool" and spec.shape is None:
        low = text.strip().lower()
        if low in _TRUE | _FALSE:
            return low in _TRUE
        raise InvalidValue(f"{where}: expected true or false, got {text!r}")
    try:
        value = json.loads(text)
    except json.JSONDecodeError:
        example = {"struct": '{"name": 1.0}'}.get(spec.base, "[1, 2, 3]" if spec.shape else "1.5")
        raise InvalidValue(f"{where}: cannot read {text!r} as {spec.name} (example: {example})"
                           ) from None
    return spec.coerce(value, where=where)


def parse_signature(text: str) -> tuple[list[tuple[str, TypeSpec]], TypeSpec | None]:
    """Split a listed function type ``(a:f64,b:f64[])->u32`` into argument and return types."""
    if not text.startswith("(") or ")->" not in text:
        raise InvalidValue(f"not a function type: {text!r}")
    inner, ret = text[1:].rsplit(")->", 1)
    args: list[tuple[str, TypeSpec]] = []
    depth, start = 0, 0
    for i, char in enumerate(inner + ","):
        if char in "{[":
            depth += 1
        elif char in "}]":
            depth -= 1
        elif char == "," and depth == 0 and inner[start:i]:
            name, _, type_name = inner[start:i].partition(":")
            args.append((name, parse_type(type_name)))
            start = i + 1
    return args, (None if ret == "none" else parse_type(ret))


def to_jsonable(value: Any) -> Any:
    """Return `value` with arrays as lists, bytes as base64 and timestamps as µs integers."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, bytes):
        return base64.b64encode(value).decode()
    if isinstance(value, TimestampUs):
        return value.t_us
    if isinstance(value, dict):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [to_jsonable(v) for v in value]
    return value


def value_to_text(value: Any) -> str:
    """Return a short human-readable rendering of `value`."""
    if isinstance(value, np.ndarray):
        return np.array2string(value, separator=", ", max_line_width=120, threshold=20)
    if isinstance(value, bytes):
        return value.hex()
    if isinstance(value, float):
        return f"{value:.12g}"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}: {value_to_text(v)}" for k, v in value.items()) + "}"
    return str(value)
