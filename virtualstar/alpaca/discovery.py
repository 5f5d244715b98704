"""Alpaca discovery: answer "alpacadiscovery1" datagrams on UDP with the HTTP port.

A client broadcasts (or sends to a host) the text `alpacadiscovery1` to UDP port
32227; every Alpaca device answers the sender with `{"AlpacaPort": <its HTTP port>}`.
The responder binds one address (loopback by default: a responder on every interface
answers the whole network, so that is an explicit choice).
"""

from __future__ import annotations

import asyncio
import json
import logging

__all__ = ["DISCOVERY_MESSAGE", "DiscoveryResponder", "answer", "start_discovery"]

log = logging.getLogger("virtualstar.alpaca")

DISCOVERY_MESSAGE = b"alpacadiscovery1"
DISCOVERY_PORT = 32227


def answer(datagram: bytes, http_port: int) -> bytes | None:
    """The reply to a datagram, or None when it is not a discovery request (version 1)."""
    if not datagram.startswith(DISCOVERY_MESSAGE):
        return None
    return json.dumps({"AlpacaPort": http_port}).encode()


class DiscoveryResponder(asyncio.DatagramProtocol):
    """Answers discovery requests; counts what it answered and ignored."""

    def __init__(self, http_port: int) -> None:
        self.http_port = http_port
        self.transport: asyncio.DatagramTransport | None = None
        self.answered = 0
        self.ignored = 0

    def connection_made(self, transport) -> None:  # type: ignore[override]
        self.transport = transport

    def datagram_received(self, data: bytes, addr) -> None:
        out = answer(data, self.http_port)
        if out is None:
            self.ignored += 1
            return
        self.answered += 1
        assert self.transport is not None
        self.transport.sendto(out, addr)

    @property
    def port(self) -> int:
        assert self.transport is not None
        return self.transport.get_extra_info("sockname")[1]

    def close(self) -> None:
        if self.transport is not None:
            self.transport.close()


async def start_discovery(bind: str, port: int, http_port: int) -> DiscoveryResponder:
    """Listen for discovery requests on UDP `bind`:`port` (0: any free port)."""
    loop = asyncio.get_running_loop()
    _transport, responder = await loop.create_datagram_endpoint(
        lambda: DiscoveryResponder(http_port), local_addr=(bind, port), allow_broadcast=True)
    log.info("Alpaca discovery on UDP %s:%d (HTTP port %d)", bind, responder.port, http_port)
    return responder
