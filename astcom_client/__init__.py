"""ASTCom: discover, read, write, call and stream every variable of a device controller.

Device side: register variables and functions in a `Collection`, serve it with an
`Endpoint`, and `publish` each block of ticks. Client side: `Client.connect(url)`.
"""

from .client import Client, MessageInfo, Stream, StreamPacket
from .codec import Codec, CodecLimits, TimestampUs
from .endpoint import Endpoint, EndpointConfig
from .exceptions import (
    AstcomError,
    AuthenticationFailed,
    AuthTimeout,
    ConnectionClosed,
    DeviceError,
    Forbidden,
    IncompatibleVersion,
    InvalidValue,
    LimitExceeded,
    MalformedFrame,
    NotWritable,
    ProtocolError,
    StateError,
    TooMany,
    UnknownMessage,
    UnknownName,
)
from .registry import Collection, Function, Variable, VariableInfo, astcom_field
from .types import TypeSpec, parse_type

__all__ = [
    "AstcomError",
    "AuthTimeout",
    "AuthenticationFailed",
    "Client",
    "Codec",
    "CodecLimits",
    "Collection",
    "ConnectionClosed",
    "DeviceError",
    "Endpoint",
    "EndpointConfig",
    "Forbidden",
    "Function",
    "IncompatibleVersion",
    "InvalidValue",
    "LimitExceeded",
    "MalformedFrame",
    "MessageInfo",
    "NotWritable",
    "ProtocolError",
    "StateError",
    "Stream",
    "StreamPacket",
    "TimestampUs",
    "TooMany",
    "TypeSpec",
    "UnknownMessage",
    "UnknownName",
    "Variable",
    "VariableInfo",
    "astcom_field",
    "parse_type",
]
