"""Errors of ASTCom, one tree, each with the numeric code it carries on the wire.

::

    AstcomError                                   .code
    ├── ProtocolError                    400   malformed or out-of-order frames
    │   ├── MalformedFrame (ValueError)  400
    │   ├── LimitExceeded (ValueError)   413   frame size, nesting depth, array length
    │   └── StateError                   409   command not allowed in this state
    ├── AuthenticationFailed (PermissionError) 401
    ├── Forbidden (PermissionError)      403   role too low for the command
    ├── UnknownName (KeyError)           404   no such variable or function
    ├── UnknownMessage (KeyError)        404   no such message ID
    ├── NotWritable (PermissionError)    405   read-only variable
    ├── AuthTimeout (TimeoutError)       408   not authenticated in time
    ├── InvalidValue (ValueError)        422   value does not fit the type
    ├── IncompatibleVersion              426
    ├── TooMany (ConnectionRefusedError) 429   clients, messages or streams beyond the limit
    ├── DeviceError (RuntimeError)       500   a device function raised
    └── ConnectionClosed (ConnectionError) 503 the connection is gone (local only)

A client turns every ERR frame back into the class of its code (`error_from_code`),
so `except KeyError` works on both sides of the wire.
"""

from __future__ import annotations

__all__ = [
    "AstcomError",
    "AuthTimeout",
    "AuthenticationFailed",
    "ConnectionClosed",
    "DeviceError",
    "Forbidden",
    "IncompatibleVersion",
    "InvalidValue",
    "LimitExceeded",
    "MalformedFrame",
    "NotWritable",
    "ProtocolError",
    "StateError",
    "TooMany",
    "UnknownMessage",
    "UnknownName",
    "error_from_code",
]


class AstcomError(Exception):
    """Base of every ASTCom error; `.code` is the numeric wire code."""

    code: int = 500

    def __init__(self, message: str = "", *, code: int | None = None) -> None:
        super().__init__(message)
        self.message = message
        if code is not None:
            self.code = code

    def __str__(self) -> str:
        return self.message


class ProtocolError(AstcomError):
    """The peer broke the protocol."""

    code = 400


class MalformedFrame(ProtocolError, ValueError):
    """A frame could not be decoded or does not have the documented layout."""

    code = 400


class LimitExceeded(ProtocolError, ValueError):
    """A frame goes beyond a security limit (size, depth, array length)."""

    code = 413


class StateError(ProtocolError):
    """A command arrived in a connection state that does not allow it."""

    code = 409


class AuthenticationFailed(AstcomError, PermissionError):
    """The challenge response did not match any role's password."""

    code = 401


class Forbidden(AstcomError, PermissionError):
    """The authenticated role may not run this command."""

    code = 403


class UnknownName(AstcomError, KeyError):
    """No variable or function has this name."""

    code = 404

    def __init__(self, message: str = "", *, name: str = "", code: int | None = None) -> None:
        super().__init__(message, code=code)
        self.name = name


class UnknownMessage(AstcomError, KeyError):
    """No message has this ID."""

    code = 404


class NotWritable(AstcomError, PermissionError):
    """The variable is read-only."""

    code = 405


class AuthTimeout(AstcomError, TimeoutError):
    """The connection was not authenticated in time."""

    code = 408


class InvalidValue(AstcomError, ValueError):
    """A value does not fit its declared type (wrong kind, out of range, wrong shape)."""

    code = 422


class IncompatibleVersion(AstcomError):
    """The peers speak different major versions of the protocol."""

    code = 426


class TooMany(AstcomError, ConnectionRefusedError):
    """A configured maximum (clients, messages, streams) is reached."""

    code = 429


class DeviceError(AstcomError, RuntimeError):
    """A device function raised while being invoked."""

    code = 500


class ConnectionClosed(AstcomError, ConnectionError):
    """The connection is closed; `.code`/`.message` give the peer's reason if it sent one."""

    code = 503


_BY_CODE: dict[int, type[AstcomError]] = {
    400: MalformedFrame,
    401: AuthenticationFailed,
    403: Forbidden,
    404: UnknownName,
    405: NotWritable,
    408: AuthTimeout,
    409: StateError,
    413: LimitExceeded,
    422: InvalidValue,
    426: IncompatibleVersion,
    429: TooMany,
    500: DeviceError,
    503: ConnectionClosed,
}


def error_from_code(code: int, message: str) -> AstcomError:
    """Build the exception that matches a wire error code (AstcomError for unknown codes)."""
    cls = _BY_CODE.get(code, AstcomError)
    return cls(message, code=code)
