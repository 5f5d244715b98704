"""The Alpaca device API rules, without I/O: parameters, transaction ids, errors, replies.

* Parameter names are case-insensitive in a GET's query string and exact in a PUT's form
  body (as ConformU checks: a PUT parameter in the wrong case is missing, HTTP 400; a
  mis-cased ClientTransactionID in a PUT is ignored).
* `ClientID` and `ClientTransactionID` are optional unsigned 32-bit integers; a value that
  is not one (an empty one included) is a bad request (HTTP 400). The reply echoes ClientTransactionID (0 when
  absent) and carries a ServerTransactionID counting from 1.
* A parameter that is missing or cannot be read as its type is HTTP 400 with a text body;
  a value that reads but is out of range is an ASCOM error (HTTP 200, InvalidValue).
* Device errors travel in `ErrorNumber` / `ErrorMessage` of an HTTP 200 reply.
* A PUT's body is a form (application/x-www-form-urlencoded, or multipart/form-data); a
  body that is not one — bytes that are not its charset's text, a %-escape that is not
  UTF-8, more than MAX_FORM_FIELDS fields, a multipart part without a name or holding a
  file, another content type — is HTTP 400 with a text body that says which, never 500.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any
from urllib.parse import parse_qsl

__all__ = ["ACTION_NOT_IMPLEMENTED", "DRIVER_ERROR", "INVALID_OPERATION", "INVALID_VALUE",
           "INVALID_WHILE_PARKED", "INVALID_WHILE_SLAVED", "NOT_CONNECTED", "NOT_IMPLEMENTED",
           "VALUE_NOT_SET", "AlpacaError", "BadParameter", "MAX_FORM_FIELDS", "Params",
           "TransactionCounter", "form_pairs", "reply"]

# ASCOM error numbers (ASCOM.ErrorCodes), as Alpaca carries them
NOT_IMPLEMENTED = 0x400
INVALID_VALUE = 0x401
VALUE_NOT_SET = 0x402
NOT_CONNECTED = 0x407
INVALID_WHILE_PARKED = 0x408
INVALID_WHILE_SLAVED = 0x409
INVALID_OPERATION = 0x40B
ACTION_NOT_IMPLEMENTED = 0x40C
DRIVER_ERROR = 0x500  # 0x500..0xFFF: the driver's own errors

_UINT32_MAX = 2**32 - 1
#: Fields a PUT's form may hold: no member takes more than a handful.
MAX_FORM_FIELDS = 64


class AlpacaError(Exception):
    """An ASCOM error for the reply's ErrorNumber / ErrorMessage (HTTP 200)."""

    def __init__(self, number: int, message: str) -> None:
        super().__init__(message)
        self.number = number
        self.message = message


class BadParameter(ValueError):
    """A request the device cannot read (HTTP 400, the message as the text body)."""


def form_pairs(body: bytes, charset: str | None = None) -> list[tuple[str, str]]:
    """Return the (name, value) pairs of an application/x-www-form-urlencoded body.

    Raises BadParameter (HTTP 400) naming what is wrong when the body is not such a form.
    """
    encoding = charset or "utf-8"
    try:
        text = body.decode(encoding)
    except LookupError:
        raise BadParameter(f"the form body's charset {charset!r} is unknown; send UTF-8 "
                           "(application/x-www-form-urlencoded)") from None
    except UnicodeDecodeError as exc:
        raise BadParameter(f"the form body is not {encoding} text (byte {exc.start} of "
                           f"{len(body)} is 0x{body[exc.start]:02X}); send "
                           "application/x-www-form-urlencoded UTF-8") from None
    try:
        return parse_qsl(text, keep_blank_values=True, encoding=encoding, errors="strict",
                         max_num_fields=MAX_FORM_FIELDS)
    except UnicodeDecodeError:
        raise BadParameter(f"a %-escape in the form body is not {encoding} text") from None
    except ValueError:
        raise BadParameter(f"the form body has more than {MAX_FORM_FIELDS} fields") from None


@dataclass(frozen=True)
class Params:
    """A request's parameters (the first value of each name): names compared without case
    (a GET's query string) or exactly (a PUT's form body, `exact`)."""

    values: dict[str, str]
    exact: bool = False

    @classmethod
    def from_pairs(cls, pairs: Iterable[tuple[str, str]], *, exact: bool = False) -> Params:
        values: dict[str, str] = {}
        for name, value in pairs:
            values.setdefault(name if exact else name.lower(), value)
        return cls(values, exact)

    def get(self, name: str) -> str | None:
        return self.values.get(name if self.exact else name.lower())

    def text(self, name: str) -> str:
        value = self.get(name)
        if value is None:
            hint = " (PUT parameter names are case-sensitive)" if self.exact else ""
            raise BadParameter(f"parameter {name} is missing{hint}")
        return value

    def number(self, name: str) -> float:
        raw = self.text(name)
        try:
            value = float(raw)
        except ValueError:
            raise BadParameter(f"parameter {name}={raw!r} is not a number") from None
        if not math.isfinite(value):
            raise BadParameter(f"parameter {name}={raw!r} is not a finite number")
        return value

    def integer(self, name: str) -> int:
        raw = self.text(name)
        try:
            return int(raw.strip())
        except ValueError:
            raise BadParameter(f"parameter {name}={raw!r} is not an integer") from None

    def boolean(self, name: str) -> bool:
        raw = self.text(name)
        word = raw.strip().lower()
        if word not in ("true", "false"):
            raise BadParameter(f"parameter {name}={raw!r} is not a boolean: expected True or "
                               "False")
        return word == "true"

    def transaction_ids(self) -> tuple[int, int]:
        """Return (ClientID, ClientTransactionID); 0 where absent; BadParameter if malformed."""
        return self._uint32("ClientID"), self._uint32("ClientTransactionID")

    def _uint32(self, name: str) -> int:
        raw = self.get(name)
        if raw is None:
            return 0
        try:
            if raw != raw.strip():
                raise ValueError(raw)
            value = int(raw)
        except ValueError:
            raise BadParameter(f"{name}={raw!r} is not an unsigned 32-bit integer") from None
        if not 0 <= value <= _UINT32_MAX:
            raise BadParameter(f"{name}={raw!r} is outside 0..{_UINT32_MAX}")
        return value


class TransactionCounter:
    """ServerTransactionID: 1, 2, 3, ... (wrapping within uint32, never 0)."""

    def __init__(self) -> None:
        self._ids = itertools.count(1)

    def next(self) -> int:
        return (next(self._ids) - 1) % _UINT32_MAX + 1


def reply(client_tid: int, server_tid: int, *, value: Any = None, has_value: bool = False,
          error: AlpacaError | None = None) -> dict[str, Any]:
    """The JSON object of a device or management reply."""
    doc: dict[str, Any] = {"ClientTransactionID": client_tid, "ServerTransactionID": server_tid,
                           "ErrorNumber": 0, "ErrorMessage": ""}
    if error is not None:
        doc["ErrorNumber"] = error.number
        doc["ErrorMessage"] = error.message
    elif has_value:
        doc["Value"] = value
    return doc
