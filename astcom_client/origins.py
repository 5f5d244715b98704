"""Which web pages may open a WebSocket to an endpoint: the check of the `Origin` header.

A browser sends `Origin` with every WebSocket handshake and lets any page connect
anywhere, so without this check a page from any site open in an engineer's browser
could drive a mount that runs without a password on loopback (cross-site WebSocket
hijacking). Non-browser clients send no `Origin`; they are not affected.
"""

from __future__ import annotations

import ipaddress
from collections.abc import Iterable
from urllib.parse import urlsplit

__all__ = ["ANY_ORIGIN", "LOOPBACK_ORIGINS", "check_allowed_origins", "normalize_origin",
           "origin_refusal"]

ANY_ORIGIN = "*"
LOOPBACK_ORIGINS = "loopback"  # http(s)://127.0.0.1, localhost or [::1], any port
_DEFAULT_PORTS = {"http": 80, "https": 443}


def normalize_origin(origin: str) -> str:
    """Return `origin` as `scheme://host[:port]` in lower case, without a default port.

    Raises ValueError when `origin` is not an http(s) origin (no path, query or user).
    """
    text = origin.strip()
    try:
        parts = urlsplit(text)
        port = parts.port
    except ValueError as exc:
        raise ValueError(f"origin {origin!r} is not scheme://host[:port]: {exc}") from None
    scheme = parts.scheme.lower()
    if (scheme not in _DEFAULT_PORTS or not parts.hostname or parts.username is not None
            or parts.path not in ("", "/") or parts.query or parts.fragment):
        raise ValueError(f"origin {origin!r} is not http(s)://host[:port] (no path, e.g. "
                         "http://127.0.0.1:8080)")
    host = parts.hostname.lower()
    host = f"[{host}]" if ":" in host else host
    if port is None or port == _DEFAULT_PORTS[scheme]:
        return f"{scheme}://{host}"
    return f"{scheme}://{host}:{port}"


def _is_loopback_origin(origin: str) -> bool:
    try:
        parts = urlsplit(normalize_origin(origin))
    except ValueError:
        return False
    return is_loopback_host(parts.hostname or "")


def is_loopback_host(host: str) -> bool:
    """True for localhost and loopback addresses (127.0.0.0/8, ::1): this machine only."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def check_allowed_origins(allowed: Iterable[str] | None) -> tuple[str, ...] | None:
    """Return `allowed` checked and normalised; raise ValueError naming a bad entry.

    None keeps the default (loopback pages only). Entries are "*" (any page),
    "loopback" (pages served from 127.0.0.1, localhost or [::1], any port) or an
    origin `http(s)://host[:port]`.
    """
    if allowed is None:
        return None
    if isinstance(allowed, str):
        raise ValueError(f"allowed_origins must be a list of origins, not the string {allowed!r}")
    checked: list[str] = []
    for entry in allowed:
        if not isinstance(entry, str):
            raise ValueError(f"allowed_origins entry {entry!r} is not a str")
        if entry in (ANY_ORIGIN, LOOPBACK_ORIGINS):
            checked.append(entry)
            continue
        try:
            checked.append(normalize_origin(entry))
        except ValueError as exc:
            raise ValueError(f"allowed_origins: {exc}; or use \"*\" or \"loopback\"") from None
    return tuple(checked)


def origin_refusal(origins: list[str], allowed: tuple[str, ...] | None) -> str | None:
    """Return why a handshake with these `Origin` header values is refused, or None.

    `origins` holds every `Origin` header of the request (none from a non-browser
    client: always accepted); `allowed` is as returned by `check_allowed_origins`.
    """
    if not origins:
        return None
    if len(origins) > 1:
        return "refused: the handshake carries several Origin headers"
    origin = origins[0]
    rules = (LOOPBACK_ORIGINS,) if allowed is None else allowed
    if ANY_ORIGIN in rules:
        return None
    if LOOPBACK_ORIGINS in rules and _is_loopback_origin(origin):
        return None
    try:
        if normalize_origin(origin) in rules:
            return None
    except ValueError:
        pass
    shown = origin[:100]
    if allowed is None:
        return (f"Origin {shown!r} refused: this ASTCom endpoint accepts browser pages served "
                "from loopback (http://127.0.0.1, localhost, [::1]) only; add the page's origin "
                "to EndpointConfig.allowed_origins to allow it")
    return (f"Origin {shown!r} refused: not in this ASTCom endpoint's allowed_origins "
            f"{list(allowed)}")
