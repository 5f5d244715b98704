"""Who may do what on the VSS: passwords and roles, and which web pages may connect.

The same challenge–response as ASTCom (`astcom_client.auth`, docs/astcom-protocol.md):
the server's `hello` carries a random nonce; the client answers with an `auth`
request holding a nonce of its own and HMAC-SHA256(password, label + both nonces);
the server compares every role's MAC in constant time, grants the highest role whose
password matches, and proves it knows the password too. The password never crosses
the wire. Roles:

* `observer`: `ping`, `status`, `errors`, `wait`, `program`, `log` and the events (watching);
* `operator`: everything else — whatever moves the mount or changes the server.
(Each command's role is in its entry of `commands.COMMANDS`.)

Hostile by assumption: before it authenticates, a connection gets a tiny `Budget`
(two requests in flight, 4 KiB messages, ten requests a second, `auth_timeout_s` to
authenticate), and at most `max_unauthenticated` such connections are open at once
(`max_unauthenticated_per_address` from one address). Authenticated connections get
a larger budget. A connection whose answers are not read uses up its requests in
flight and is then no longer read (back-pressure), so it buffers nothing without
bound. Password attempts are throttled per address and overall (`AuthThrottle`,
astcom_client/throttle.py) and each wrong one is logged with the address.

Without passwords every connection is an operator; that is allowed on loopback only
(`check_listen`). Browsers send `Origin` with a WebSocket handshake: pages not served
from loopback, or from an origin on the allow-list, are refused (HTTP 403), so a web
page open in the operator's browser cannot drive the telescope.

`Session` is the per-connection state, without I/O; the server pumps it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from astcom_client.auth import MIN_CLIENT_NONCE_BYTES, Authenticator, Role, new_nonce
from astcom_client.origins import check_allowed_origins, is_loopback_host, origin_refusal
from astcom_client.throttle import ThrottlePolicy

from .exceptions import BadRequest, Forbidden, Unauthorized

__all__ = ["AUTHENTICATED", "UNAUTHENTICATED", "AccessConfig", "AuthAttempt", "Budget",
           "Session", "check_listen", "refuse_origin"]

MAX_AUTH_FAILURES = 3  # then the connection is closed


@dataclass(frozen=True)
class Budget:
    """What one connection may use: requests handled at once, message size, request rate."""

    in_flight: int  # requests being handled or answered at once; beyond, it is not read
    message_bytes: int  # a larger message closes the connection (WebSocket code 1009)
    rate_per_s: float | None = None  # requests read per second (None: no limit)
    burst: int = 0  # ... after a burst of this many


UNAUTHENTICATED = Budget(in_flight=2, message_bytes=4096, rate_per_s=10.0, burst=10)
AUTHENTICATED = Budget(in_flight=64, message_bytes=1 << 20)


@dataclass(frozen=True)
class AccessConfig:
    """Passwords per role ({"operator": ..., "observer": ...}, None: none), allowed
    origins, and the limits on connections that have not authenticated."""

    passwords: Mapping[str, str] | None = None
    allowed_origins: Sequence[str] | None = None  # None: pages from loopback only
    throttle: ThrottlePolicy = field(default_factory=ThrottlePolicy)
    unauthenticated: Budget = UNAUTHENTICATED
    authenticated: Budget = AUTHENTICATED
    auth_timeout_s: float = 30.0
    max_unauthenticated: int = 128
    max_unauthenticated_per_address: int = 16

    def __post_init__(self) -> None:
        try:
            object.__setattr__(self, "_auth", Authenticator(self.passwords))
            object.__setattr__(self, "allowed_origins",
                               check_allowed_origins(self.allowed_origins))
        except ValueError as exc:
            raise BadRequest(f"server access: {exc}") from None

    @property
    def authenticator(self) -> Authenticator:
        return self._auth  # type: ignore[attr-defined]

    @property
    def required(self) -> bool:
        return self.authenticator.required


def check_listen(host: str, access: AccessConfig) -> None:
    """Refuse to listen beyond loopback without passwords (anyone on the network could drive)."""
    if access.required:
        return
    if is_loopback_host(host):
        return
    raise BadRequest(f"listening on {host} without passwords would let anyone on the network "
                     "move the telescope: give --operator-password (and --observer-password), "
                     "or listen on 127.0.0.1")


def refuse_origin(origins: list[str], access: AccessConfig) -> str | None:
    """Return why a browser page may not connect (HTTP 403), or None."""
    reason = origin_refusal(origins, access.allowed_origins)
    if reason is None:
        return None
    return (f"Origin {origins[0][:100]!r} refused: the VirtualStar Server accepts browser pages "
            "served from loopback only, unless started with --allow-origin ORIGIN")


@dataclass(frozen=True)
class AuthAttempt:
    """A well-formed `auth` request, not yet checked."""

    client_nonce: bytes
    mac: bytes
    requested: Role | None


class Session:
    """One connection's authentication state and role."""

    def __init__(self, access: AccessConfig) -> None:
        self.access = access
        self.nonce = new_nonce()
        self.role = Role.NONE if access.required else Role.OPERATOR
        self.failures = 0

    def hello(self) -> dict[str, Any]:
        """The `auth` part of the hello event."""
        return {"required": self.access.required, "nonce": self.nonce.hex(),
                "role": self.role.label if self.role else None}

    @property
    def budget(self) -> Budget:
        return self.access.authenticated if self.role else self.access.unauthenticated

    @property
    def closed_for_failures(self) -> bool:
        return self.failures >= MAX_AUTH_FAILURES

    def parse_auth(self, params: dict[str, Any]) -> AuthAttempt | None:
        """Check the layout of an `auth` request; None when the server needs no password.

        Raises BadRequest for a malformed one, Unauthorized once this connection has
        used up its attempts.
        """
        if not self.access.required:
            return None
        if self.closed_for_failures:  # several auth requests in flight at once: no more guesses
            raise Unauthorized("too many wrong passwords; closing the connection")
        unknown = sorted(set(params) - {"client_nonce", "mac", "role"})
        if unknown:
            raise BadRequest(f"auth: unknown parameters {unknown[:10]}; valid: client_nonce, "
                             "mac, role")
        nonce_hex, mac_hex = params.get("client_nonce", ""), params.get("mac", "")
        if not isinstance(nonce_hex, str) or not isinstance(mac_hex, str) \
                or len(nonce_hex) > 512 or len(mac_hex) != 64:
            raise BadRequest(f"auth: expected a client_nonce of {MIN_CLIENT_NONCE_BYTES} to 256 "
                             "bytes and a 32-byte HMAC-SHA256 mac, as hex text")
        try:
            client_nonce, mac = bytes.fromhex(nonce_hex), bytes.fromhex(mac_hex)
        except ValueError:
            raise BadRequest("auth: client_nonce and mac must be hex text") from None
        if len(client_nonce) < MIN_CLIENT_NONCE_BYTES:
            raise BadRequest(f"auth: expected a client_nonce of at least "
                             f"{MIN_CLIENT_NONCE_BYTES} bytes")
        requested = params.get("role")
        if requested not in (None, "observer", "operator"):
            raise BadRequest(f"auth: role {str(requested)[:20]!r}: expected 'observer' or "
                             "'operator'")
        return AuthAttempt(client_nonce, mac,
                           None if requested is None else Role[str(requested).upper()])

    def refused(self, message: str) -> Unauthorized:
        """Count an attempt refused unchecked (throttled) against this connection."""
        self.failures += 1
        return Unauthorized(message + ("; closing the connection"
                                       if self.closed_for_failures else ""))

    def verify(self, attempt: AuthAttempt) -> dict[str, Any]:
        """Check the password of `attempt`; return {"role", "server_proof", "nonce"};
        raise Unauthorized for a wrong one."""
        role, proof = self.access.authenticator.verify(
            self.nonce, attempt.client_nonce, attempt.mac, attempt.requested)
        if role == Role.NONE:
            self.failures += 1
            raise Unauthorized("wrong password" + ("; closing the connection"
                                                   if self.closed_for_failures else ""))
        self.nonce = new_nonce()  # a captured answer cannot be replayed on this connection
        self.role = role
        return {"role": role.label, "server_proof": proof.hex(), "nonce": self.nonce.hex()}

    def permit(self, cmd: str, needed: Role, watching: str = "") -> None:
        """Raise Unauthorized/Forbidden when this connection may not send `cmd` (which
        needs the role `needed`); `watching` lists what an observer may send."""
        if self.role >= needed:
            return
        if self.role == Role.NONE:
            raise Unauthorized(f"{cmd[:64]}: authenticate first: this server needs a password "
                               "(vs --password PW, or VS_PASSWORD)")
        raise Forbidden(f"{cmd}: the observer role may only watch ({watching}); log in with "
                        "the operator password to move or configure the telescope")

    @property
    def may_watch(self) -> bool:
        return self.role >= Role.OBSERVER
