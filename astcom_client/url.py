"""Parse ASTCom URLs: ws://, wss://, tcp:// and tls:// with a host and a port."""

from __future__ import annotations

from dataclasses import dataclass
from urllib.parse import urlsplit

__all__ = ["DEFAULT_PORT", "SCHEMES", "EndpointUrl", "parse_url"]

SCHEMES = ("ws", "wss", "tcp", "tls")
DEFAULT_PORT = 8765


@dataclass(frozen=True)
class EndpointUrl:
    """A parsed endpoint address."""

    scheme: str
    host: str
    port: int
    path: str = "/"

    @property
    def secure(self) -> bool:
        return self.scheme in ("wss", "tls")

    @property
    def websocket(self) -> bool:
        return self.scheme in ("ws", "wss")

    def __str__(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        path = self.path if self.websocket and self.path != "/" else ""
        return f"{self.scheme}://{host}:{self.port}{path}"


def parse_url(url: str) -> EndpointUrl:
    """Parse `url`; raise ValueError saying what is expected."""
    expected = "expected ws://HOST:PORT, wss://HOST:PORT, tcp://HOST:PORT or tls://HOST:PORT"
    try:
        parts = urlsplit(url)
        port = parts.port
    except ValueError as exc:
        raise ValueError(f"invalid URL {url!r}: {exc}; {expected}") from None
    if parts.scheme not in SCHEMES:
        raise ValueError(f"invalid URL {url!r}: unknown scheme {parts.scheme!r}; {expected}")
    if not parts.hostname:
        raise ValueError(f"invalid URL {url!r}: no host; {expected}")
    return EndpointUrl(parts.scheme, parts.hostname, DEFAULT_PORT if port is None else port,
                       parts.path or "/")
