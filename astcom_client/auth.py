"""Authenticate a connection by challenge–response; the password never crosses the wire.

The server sends a random nonce in its HELLO reply. The client answers with a nonce
of its own and ``HMAC-SHA256(key=password, msg=CLIENT_LABEL + server_nonce + client_nonce)``.
The server recomputes the MAC for every role's password and compares each in constant
time (`hmac.compare_digest`); the highest role whose password matches is granted. It
proves it knows the password too, with ``HMAC-SHA256(password, SERVER_LABEL + ...)``.
"""

from __future__ import annotations

import hashlib
import hmac
import os
from collections.abc import Mapping
from enum import IntEnum

__all__ = ["CLIENT_LABEL", "SERVER_LABEL", "Authenticator", "Role", "client_mac", "server_proof"]

CLIENT_LABEL = b"ASTCom-1 client\x00"
SERVER_LABEL = b"ASTCom-1 server\x00"
NONCE_BYTES = 32
MIN_CLIENT_NONCE_BYTES = 16


class Role(IntEnum):
    """What an authenticated connection may do; a higher role may do all a lower one can."""

    NONE = 0
    OBSERVER = 1  # list, read, stream
    OPERATOR = 2  # also write, invoke

    @property
    def label(self) -> str:
        return self.name.lower()


ROLE_BY_NAME = {r.label: r for r in (Role.OBSERVER, Role.OPERATOR)}


def client_mac(password: str, server_nonce: bytes, client_nonce: bytes) -> bytes:
    """Return the client's proof of knowing `password` (32 bytes)."""
    msg = CLIENT_LABEL + server_nonce + client_nonce
    return hmac.new(password.encode("utf-8"), msg, hashlib.sha256).digest()


def server_proof(password: str, server_nonce: bytes, client_nonce: bytes) -> bytes:
    """Return the server's proof of knowing `password` (32 bytes)."""
    msg = SERVER_LABEL + server_nonce + client_nonce
    return hmac.new(password.encode("utf-8"), msg, hashlib.sha256).digest()


def new_nonce() -> bytes:
    """Return a fresh random server nonce."""
    return os.urandom(NONCE_BYTES)


class Authenticator:
    """Check challenge responses against the configured role passwords.

    With `passwords` None, authentication is off and every connection is an operator
    (for loopback tests and demos only).
    """

    def __init__(self, passwords: Mapping[str, str] | None) -> None:
        self._passwords: dict[Role, str] = {}
        if passwords is not None:
            for name, password in passwords.items():
                role = ROLE_BY_NAME.get(name)
                if role is None:
                    raise ValueError(f"unknown role {name!r}; expected one of {sorted(ROLE_BY_NAME)}")
                if not isinstance(password, str) or not password:
                    raise ValueError(f"the {name} password must be a non-empty string")
                self._passwords[role] = password
            if not self._passwords:
                raise ValueError("passwords is empty; give at least one role or None to disable auth")

    @property
    def required(self) -> bool:
        return bool(self._passwords)

    def verify(self, server_nonce: bytes, client_nonce: bytes, mac: bytes,
               requested: Role | None = None) -> tuple[Role, bytes]:
        """Return (granted role, server proof), or (Role.NONE, b"") when no password matches.

        Every role's MAC is computed and compared, so the time taken does not say which
        role (if any) came close.
        """
        granted, proof = Role.NONE, b""
        for role, password in sorted(self._passwords.items()):
            expected = client_mac(password, server_nonce, client_nonce)
            if hmac.compare_digest(expected, mac):
                granted, proof = role, server_proof(password, server_nonce, client_nonce)
        if requested is not None and granted > requested:
            granted = requested
        return granted, proof
