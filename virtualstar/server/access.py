"""Who may do what on the VSS: passwords and roles, and which web pages may connect.

The same challenge–response as ASTCom (`astcom_client.auth`, docs/astcom-protocol.md):
the server's `hello` carries a random nonce; the client answers with an `auth`
request holding a nonce of its own and HMAC-SHA256(password, label + both nonces);
the server compares every role's MAC in constant time, grants the highest role whose
password matches, and proves it knows the password too. The password never crosses
the wire. Roles:

* `observer`: `ping`, `status`, `errors`, `wait`, `program`, `log` and the events (watching);
* `operator`: everything else — whatever moves the mount or changes the server.

Without passwords every connection is an operator; that is allowed on loopback only
(`check_listen`). Browsers send `Origin` with a WebSocket handshake: pages not served
from loopback, or from an origin on the allow-list, are refused (HTTP 403), so a web
page open in the operator's browser cannot drive the telescope.

`Session` is the per-connection state, without I/O; the server pumps it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from astcom_client.auth import MIN_CLIENT_NONCE_BYTES, Authenticator, Role, new_nonce
from astcom_client.origins import check_allowed_origins, is_loopback_host, origin_refusal

from .exceptions import BadRequest, Forbidden, Unauthorized

__all__ = ["OBSERVER_COMMANDS", "AccessConfig", "Session", "check_listen", "refuse_origin"]

OPEN_COMMANDS = frozenset({"ping", "auth"})  # allowed before authenticating
OBSERVER_COMMANDS = frozenset({"ping", "auth", "status", "errors", "wait", "program", "log"})
MAX_AUTH_FAILURES = 3  # then the connection is closed


@dataclass(frozen=True)
class AccessConfig:
    """Passwords per role ({"operator": ..., "observer": ...}, None: none) and allowed origins."""

    passwords: Mapping[str, str] | None = None
    allowed_origins: Sequence[str] | None = None  # None: pages from loopback only

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
    def closed_for_failures(self) -> bool:
        return self.failures >= MAX_AUTH_FAILURES

    def authenticate(self, params: dict[str, Any]) -> dict[str, Any]:
        """Check an `auth` request; return {"role", "server_proof"}; raise Unauthorized."""
        if not self.access.required:
            return {"role": self.role.label, "server_proof": None}
        if self.closed_for_failures:  # several auth requests in flight at once: no more guesses
            raise Unauthorized("too many wrong passwords; closing the connection")
        unknown = sorted(set(params) - {"client_nonce", "mac", "role"})
        if unknown:
            raise BadRequest(f"auth: unknown parameters {unknown}; valid: client_nonce, mac, role")
        try:
            client_nonce = bytes.fromhex(str(params.get("client_nonce", "")))
            mac = bytes.fromhex(str(params.get("mac", "")))
        except ValueError:
            raise BadRequest("auth: client_nonce and mac must be hex text") from None
        if len(client_nonce) < MIN_CLIENT_NONCE_BYTES or len(mac) != 32:
            raise BadRequest(f"auth: expected a client_nonce of at least {MIN_CLIENT_NONCE_BYTES} "
                             "bytes and a 32-byte HMAC-SHA256 mac, as hex")
        requested = params.get("role")
        if requested not in (None, "observer", "operator"):
            raise BadRequest(f"auth: role {requested!r}: expected 'observer' or 'operator'")
        role, proof = self.access.authenticator.verify(
            self.nonce, client_nonce, mac,
            None if requested is None else Role[str(requested).upper()])
        if role == Role.NONE:
            self.failures += 1
            raise Unauthorized("wrong password" + ("; closing the connection"
                                                   if self.closed_for_failures else ""))
        self.nonce = new_nonce()  # a captured answer cannot be replayed on this connection
        self.role = role
        return {"role": role.label, "server_proof": proof.hex(), "nonce": self.nonce.hex()}

    def permit(self, cmd: str) -> None:
        """Raise Unauthorized/Forbidden when this connection may not send `cmd`."""
        if self.role == Role.NONE and cmd not in OPEN_COMMANDS:
            raise Unauthorized(f"{cmd}: authenticate first: this server needs a password "
                               "(vs --password PW, or VS_PASSWORD)")
        if self.role == Role.OBSERVER and cmd not in OBSERVER_COMMANDS:
            watching = ", ".join(sorted(OBSERVER_COMMANDS - OPEN_COMMANDS))
            raise Forbidden(f"{cmd}: the observer role may only watch ({watching}); log in "
                            "with the operator password to move or configure the telescope")

    @property
    def may_watch(self) -> bool:
        return self.role >= Role.OBSERVER
