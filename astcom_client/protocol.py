"""The ASTCom connection logic without I/O: frames in, events and frames out.

`ServerConnection` and `ClientConnection` take whole frames (one msgpack value each;
the transports cut the byte stream into frames) with `receive_frame(bytes)` and return
events; the frames they want sent come out of `next_frame()`. Neither imports asyncio
nor socket, so both are tested in memory, byte for byte.
"""

from __future__ import annotations

import hmac
import os
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any

from .auth import (
    MIN_CLIENT_NONCE_BYTES,
    ROLE_BY_NAME,
    Authenticator,
    Role,
    client_mac,
    new_nonce,
    server_proof,
)
from .codec import Codec
from .commands import (
    COMMANDS,
    MAX_SEQ,
    PROTOCOL_VERSION,
    Auth,
    Bye,
    Command,
    DataFrame,
    Hello,
    decode_request,
)
from .exceptions import (
    AstcomError,
    AuthenticationFailed,
    ConnectionClosed,
    Forbidden,
    IncompatibleVersion,
    LimitExceeded,
    MalformedFrame,
    ProtocolError,
    StateError,
    TooMany,
    error_from_code,
)

__all__ = [
    "AuthRequested",
    "ClientConnection",
    "ClientState",
    "ConnectionTerminated",
    "DataReceived",
    "Failure",
    "Ready",
    "Reply",
    "RequestReceived",
    "ServerConnection",
    "ServerState",
]


# -- events ------------------------------------------------------------------------------
@dataclass(frozen=True)
class RequestReceived:
    """A checked, authorised request the device side must answer (server side)."""

    seq: int
    command: Command


@dataclass(frozen=True)
class AuthRequested:
    """An AUTH the endpoint may hold (throttling) before `ServerConnection.finish_auth`
    checks it; only with `ServerOptions.gate_auth` (server side)."""

    seq: int
    auth: Auth


@dataclass(frozen=True)
class ConnectionTerminated:
    """The connection is over; `code`/`reason` say why (both sides)."""

    code: int
    reason: str


@dataclass(frozen=True)
class Ready:
    """The handshake is complete (client side)."""

    role: Role
    hello: dict[str, Any]


@dataclass(frozen=True)
class Reply:
    """A successful reply to request `seq` (client side)."""

    seq: int
    result: dict[str, Any]


@dataclass(frozen=True)
class Failure:
    """An error reply to request `seq` (client side); seq None for connection-level errors."""

    seq: int | None
    error: AstcomError


@dataclass(frozen=True)
class DataReceived:
    """A stream packet (client side)."""

    data: DataFrame


# -- server ------------------------------------------------------------------------------
class ServerState(IntEnum):
    AWAIT_HELLO = 0
    AWAIT_AUTH = 1
    READY = 2
    CLOSED = 3


# Rules: a connection must say HELLO first, then AUTH (skipped when authentication is off),
# then may send any other command; PING and BYE are allowed at any time. A command not in
# the row of the current state is answered with StateError (409) and not executed. The
# value is the state after the command succeeds.
_AFTER_AUTH = {op: ServerState.READY for op in COMMANDS if op not in ("HELLO", "AUTH")}
SERVER_TRANSITIONS: dict[ServerState, dict[str, ServerState]] = {
    ServerState.AWAIT_HELLO: {"HELLO": ServerState.AWAIT_AUTH, "PING": ServerState.AWAIT_HELLO,
                              "BYE": ServerState.CLOSED},
    ServerState.AWAIT_AUTH: {"AUTH": ServerState.READY, "PING": ServerState.AWAIT_AUTH,
                             "BYE": ServerState.CLOSED},
    ServerState.READY: {**_AFTER_AUTH, "BYE": ServerState.CLOSED},
    ServerState.CLOSED: {},
}
MAX_PROTOCOL_ERRORS = 8  # an authenticated peer that keeps sending garbage is cut off


@dataclass
class ServerOptions:
    """What the server announces and enforces per connection."""

    authenticator: Authenticator
    codec: Codec
    server_name: str = "astcom"
    loop_rate_hz: float = 1000.0
    queue_packets: int = 256
    limits: dict[str, Any] = field(default_factory=dict)
    # Called just before a connection becomes authenticated; returns why it is refused
    # (ERR 429, then closed) or None. The endpoint counts its authenticated clients here.
    admit: Callable[[], str | None] | None = None
    # True: an AUTH is handed out as `AuthRequested` and checked by `finish_auth`, so the
    # endpoint can hold or refuse it first (password attempts throttled).
    gate_auth: bool = False


class ServerConnection:
    """One client as seen by the endpoint: handshake, state, authorisation, outbox.

    The outbox holds control frames (replies, never dropped) and stream frames (at most
    `queue_packets`; when full the oldest is dropped and its samples counted in
    `dropped_samples`).
    """

    def __init__(self, options: ServerOptions, *, client_id: int = 0) -> None:
        self.options = options
        self.client_id = client_id
        self.state = ServerState.AWAIT_HELLO
        self.role = Role.NONE
        self.peer_name = ""
        self.close_code = 0
        self.close_reason = ""
        self.dropped_samples = 0
        self.dropped_packets = 0
        self.protocol_errors = 0
        self._nonce = b""
        self._control: deque[bytes] = deque()
        self._stream: deque[tuple[bytes, int]] = deque()

    # -- input ----------------------------------------------------------------------------
    def receive_frame(self, data: bytes) -> list[RequestReceived | ConnectionTerminated]:
        """Digest one frame; return the requests to execute (and a termination if any)."""
        if self.state is ServerState.CLOSED:
            return []
        seq: int | None = None
        try:
            frame = self.options.codec.decode(data)
            # ERR carries the request's seq only when it is a valid one (§3); else nil
            if (isinstance(frame, list) and len(frame) == 3 and type(frame[1]) is int
                    and 0 <= frame[1] <= MAX_SEQ):
                seq = frame[1]
            seq, command = decode_request(frame)
            return self._dispatch(seq, command)
        except LimitExceeded as exc:
            return self._fail(seq, exc, close=True)
        except ProtocolError as exc:
            self.protocol_errors += 1
            fatal = self.role is Role.NONE or self.protocol_errors >= MAX_PROTOCOL_ERRORS
            return self._fail(seq, exc, close=fatal)
        except AstcomError as exc:
            return self._fail(seq, exc, close=self.state is ServerState.CLOSED)

    def _dispatch(self, seq: int, command: Command) -> list[RequestReceived | ConnectionTerminated]:
        following = SERVER_TRANSITIONS[self.state].get(command.OP)
        if following is None:
            wanted = "HELLO" if self.state is ServerState.AWAIT_HELLO else "AUTH"
            raise StateError(f"{command.OP} is not allowed before {wanted}"
                             if self.state < ServerState.READY
                             else f"{command.OP} is not allowed after the handshake")
        if self.role < command.ROLE:
            raise Forbidden(f"{command.OP} needs the {command.ROLE.label} role; this connection "
                            f"is {self.role.label}")
        if isinstance(command, Hello):
            self._hello(seq, command)
            return []
        if isinstance(command, Auth):
            if self.options.gate_auth:
                return [AuthRequested(seq, command)]
            return self._auth(seq, command)
        if isinstance(command, Bye):
            self.send_result(seq, {})
            return self.close(1000, "bye", send_error=False)
        return [RequestReceived(seq, command)]

    def _hello(self, seq: int, hello: Hello) -> None:
        major = hello.version.split(".")[0]
        if major != PROTOCOL_VERSION.split(".")[0]:
            refusal = IncompatibleVersion(f"protocol version {hello.version!r} is not "
                                          f"supported; this endpoint speaks {PROTOCOL_VERSION}")
            # the reason goes into the close too; the ERR reply is sent by receive_frame
            self.close(refusal.code, refusal.message, send_error=False)
            raise refusal
        self.peer_name = hello.client[:64]
        auth = self.options.authenticator
        if not auth.required:
            self._admit()
        self._nonce = new_nonce() if auth.required else b""
        self.state = ServerState.AWAIT_AUTH if auth.required else ServerState.READY
        if not auth.required:
            self.role = Role.OPERATOR
        self.send_result(seq, {
            "version": PROTOCOL_VERSION,
            "server": self.options.server_name,
            "auth": "hmac-sha256" if auth.required else None,
            "nonce": self._nonce,
            "role": self.role.label if self.role else None,
            "loop_rate_hz": float(self.options.loop_rate_hz),  # a float, as §5 says
            "limits": self.options.limits,
        })

    def _auth(self, seq: int, auth: Auth) -> list[RequestReceived | ConnectionTerminated]:
        if len(auth.cnonce) < MIN_CLIENT_NONCE_BYTES or len(auth.cnonce) > 256:
            raise MalformedFrame(f"AUTH: cnonce must hold {MIN_CLIENT_NONCE_BYTES}..256 bytes")
        requested = None
        if auth.role is not None:
            requested = ROLE_BY_NAME.get(auth.role)
            if requested is None:
                raise MalformedFrame(f"AUTH: unknown role {auth.role!r}; expected observer or operator")
        role, proof = self.options.authenticator.verify(self._nonce, auth.cnonce, auth.mac, requested)
        if role is Role.NONE:
            self.state = ServerState.CLOSED
            raise AuthenticationFailed("authentication failed: wrong password")
        self._admit()
        self.role = role
        self.state = ServerState.READY
        self.send_result(seq, {"role": role.label, "proof": proof})
        return []

    def finish_auth(self, seq: int, auth: Auth, refusal: str | None = None
                    ) -> list[ConnectionTerminated]:
        """Check a held AUTH (`AuthRequested`), or refuse it unchecked with `refusal`
        (ERR 429, then closed). A wrong password closes the connection (ERR 401)."""
        if self.state is not ServerState.AWAIT_AUTH:  # closed meanwhile (auth timeout)
            return []
        try:
            if refusal is not None:
                self.state = ServerState.CLOSED
                raise TooMany(refusal)
            return self._auth(seq, auth)
        except AstcomError as exc:  # still unauthenticated: every error ends the connection
            return self._fail(seq, exc, close=True)

    def _admit(self) -> None:
        refusal = self.options.admit() if self.options.admit is not None else None
        if refusal is not None:
            self.state = ServerState.CLOSED
            raise TooMany(refusal)

    def _fail(self, seq: int | None, exc: AstcomError, *, close: bool) -> list[Any]:
        self.send_error(seq, exc)
        if close:
            return self.close(exc.code, exc.message, send_error=False)
        return []

    # -- output ---------------------------------------------------------------------------
    def send_result(self, seq: int, result: dict[str, Any]) -> None:
        """Queue the reply ["OK", seq, result]."""
        self._control.append(self.options.codec.encode(["OK", seq, result]))

    def send_error(self, seq: int | None, exc: AstcomError) -> None:
        """Queue the reply ["ERR", seq, {"code", "message"}]."""
        body = {"code": exc.code, "message": exc.message[:1024]}
        self._control.append(self.options.codec.encode(["ERR", seq, body]))

    def push_stream(self, frame: bytes, n_samples: int) -> None:
        """Queue an encoded DATA frame, dropping (and counting) the oldest when full."""
        if self.state is ServerState.CLOSED:
            return
        stream = self._stream
        if len(stream) >= self.options.queue_packets:
            _, lost = stream.popleft()
            self.dropped_packets += 1
            self.dropped_samples += lost
        stream.append((frame, n_samples))

    def next_frame(self) -> bytes | None:
        """Return the next frame to send (replies before stream packets), or None."""
        if self._control:
            return self._control.popleft()
        if self._stream and self.state is not ServerState.CLOSED:
            return self._stream.popleft()[0]
        return None

    def next_stream(self) -> bytes | None:
        """Return the next stream packet to send, or None."""
        if self._stream and self.state is not ServerState.CLOSED:
            return self._stream.popleft()[0]
        return None

    def next_control(self) -> bytes | None:
        """Return the next reply frame to send, or None (stream packets stay queued)."""
        return self._control.popleft() if self._control else None

    @property
    def has_control(self) -> bool:
        return bool(self._control)

    @property
    def queue_depth(self) -> int:
        """Return the number of stream packets waiting to be sent."""
        return len(self._stream)

    def close(self, code: int, reason: str, *, send_error: bool = True) -> list[Any]:
        """End the connection with a reason; the pending replies are still sent."""
        if self.close_code == 0:
            self.close_code, self.close_reason = code, reason
            if send_error and reason:
                self.send_error(None, error_from_code(code, reason))
        self.state = ServerState.CLOSED
        self._stream.clear()
        return [ConnectionTerminated(code, reason)]


# -- client ------------------------------------------------------------------------------
class ClientState(IntEnum):
    IDLE = 0
    HELLO_SENT = 1
    AUTH_SENT = 2
    READY = 3
    CLOSED = 4


class ClientConnection:
    """The client side: runs the handshake, numbers requests, sorts incoming frames."""

    def __init__(self, codec: Codec, *, password: str | None = None, role: str | None = None,
                 client_name: str = "astcom-client") -> None:
        self.codec = codec
        self.password = password
        self.requested_role = role
        self.client_name = client_name
        self.state = ClientState.IDLE
        self.role = Role.NONE
        self.hello: dict[str, Any] = {}
        self._next_seq = 1
        self._handshake_seq = 0
        self._cnonce = b""
        self._outbox: deque[bytes] = deque()

    def start(self) -> None:
        """Queue HELLO."""
        self._handshake_seq = self._queue(Hello(PROTOCOL_VERSION, self.client_name))
        self.state = ClientState.HELLO_SENT

    def send(self, command: Command) -> int:
        """Queue a request and return its seq."""
        if self.state is ClientState.CLOSED:
            raise ConnectionClosed("the connection is closed")
        return self._queue(command)

    def _queue(self, command: Command) -> int:
        seq = self._next_seq
        self._next_seq += 1
        self._outbox.append(self.codec.encode(command.to_frame(seq)))
        return seq

    def next_frame(self) -> bytes | None:
        """Return the next frame to send, or None."""
        return self._outbox.popleft() if self._outbox else None

    @property
    def has_output(self) -> bool:
        return bool(self._outbox)

    def receive_frame(self, data: bytes) -> list[Any]:
        """Digest one frame from the server; return Reply/Failure/DataReceived/Ready events."""
        frame = self.codec.decode(data)
        if not isinstance(frame, list) or not frame or not isinstance(frame[0], str):
            raise MalformedFrame("a server frame is an array starting with OK, ERR or DATA")
        kind = frame[0]
        if kind == "DATA":
            return [DataReceived(DataFrame.from_frame(frame))]
        if len(frame) != 3 or not (frame[1] is None or isinstance(frame[1], int)):
            raise MalformedFrame(f"a {kind} frame is [{kind}, seq, map]")
        seq, body = frame[1], frame[2]
        if not isinstance(body, dict):
            raise MalformedFrame(f"a {kind} frame carries a map")
        if kind == "ERR":
            error = error_from_code(int(body.get("code", 500)), str(body.get("message", "")))
            if seq is not None and seq == self._handshake_seq and self.state < ClientState.READY:
                self.state = ClientState.CLOSED
            return [Failure(seq, error)]
        if kind != "OK":
            raise MalformedFrame(f"unknown server frame kind {kind!r}")
        if seq == self._handshake_seq and self.state in (ClientState.HELLO_SENT, ClientState.AUTH_SENT):
            return self._handshake(body)
        return [Reply(seq, body)]

    def _handshake(self, body: dict[str, Any]) -> list[Any]:
        if self.state is ClientState.HELLO_SENT:
            self.hello = body
            if body.get("auth") is None:
                self.state = ClientState.READY
                self.role = ROLE_BY_NAME.get(str(body.get("role")), Role.OPERATOR)
                return [Ready(self.role, body)]
            if self.password is None:
                self.state = ClientState.CLOSED
                return [Failure(None, AuthenticationFailed(
                    "the endpoint requires a password (give --password or ASTCOM_PASSWORD)"))]
            nonce = body.get("nonce")
            if not isinstance(nonce, bytes):
                raise MalformedFrame("HELLO reply without a binary nonce")
            self._cnonce = os.urandom(32)
            mac = client_mac(self.password, nonce, self._cnonce)
            self._handshake_seq = self._queue(Auth(self._cnonce, mac, self.requested_role))
            self.state = ClientState.AUTH_SENT
            return []
        assert self.password is not None
        expected = server_proof(self.password, self.hello["nonce"], self._cnonce)
        if not hmac.compare_digest(expected, body.get("proof", b"")):
            self.state = ClientState.CLOSED
            return [Failure(None, AuthenticationFailed(
                "the endpoint did not prove it knows the password (impostor?)"))]
        self.role = ROLE_BY_NAME.get(str(body.get("role")), Role.NONE)
        self.state = ClientState.READY
        return [Ready(self.role, self.hello)]
