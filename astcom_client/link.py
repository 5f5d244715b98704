"""The framed link of docs/astcom-protocol.md §11, without I/O: bytes in, link frames out.

One byte stream (a UART, SPI, a pty, a TCP pipe) carries many ASTCom connections, one
per channel. Each link frame is ``COBS(chan u8, kind u8, body, crc32 u32 LE) 0x00``: COBS
(the `cobs` package) removes every zero byte so a 0x00 always ends a frame and a
receiver that lost its place finds the next frame at the next 0x00; the CRC is zlib's
crc32 over chan, kind and body. A damaged frame is counted and skipped, nothing else.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass
from enum import IntEnum

from cobs import cobs

__all__ = ["LINK_VERSION", "LinkFrame", "LinkKind", "LinkReader", "encode_link_frame",
           "link_hello_body", "parse_link_hello"]

LINK_VERSION = 1


class LinkKind(IntEnum):
    DATA = 1   # an ASTCom frame of the channel, either way
    OPEN = 2   # relay -> device: a client arrived on the channel (body: its address, text)
    CLOSE = 3  # either way: the channel is over; from the device: u16 LE code + reason
    HELLO = 4  # channel 0: u8 version, u16 LE channels, u32 LE max_frame_bytes, u32 LE token
    PING = 5   # channel 0, relay -> device: a token (4 bytes)
    PONG = 6   # channel 0, device -> relay: the same token


@dataclass(frozen=True)
class LinkFrame:
    chan: int
    kind: int
    body: bytes


def encode_link_frame(chan: int, kind: int, body: bytes = b"") -> bytes:
    """Return the bytes of one link frame, its 0x00 delimiter included."""
    plain = bytes((chan, kind)) + body
    return cobs.encode(plain + struct.pack("<I", zlib.crc32(plain))) + b"\0"


def link_hello_body(channels: int, max_frame_bytes: int, token: int = 0) -> bytes:
    """A HELLO body; `token` is the relay's (1..2^32-1) or, from the device, the token of
    the HELLO it answers (0 when it announces itself at boot)."""
    return struct.pack("<BHII", LINK_VERSION, channels, max_frame_bytes, token)


def parse_link_hello(body: bytes) -> tuple[int, int, int, int | None]:
    """Return (version, channels, max_frame_bytes, token) of a HELLO body (token None from
    a device that sends none); ValueError if short."""
    if len(body) < 7:
        raise ValueError(f"link HELLO of {len(body)} bytes; expected 11")
    version, channels, max_frame = struct.unpack_from("<BHI", body)
    token = struct.unpack_from("<I", body, 7)[0] if len(body) >= 11 else None
    return version, channels, max_frame, token


class LinkReader:
    """Cut received bytes into link frames; skip (and count) damaged or oversized ones."""

    def __init__(self, max_body_bytes: int) -> None:
        self.max_encoded = max_body_bytes + 6 + (max_body_bytes + 6) // 254 + 2
        self._buf = bytearray()
        self._skipping = False
        self.crc_errors = 0
        self.framing_errors = 0
        self.oversize = 0

    def feed(self, data: bytes) -> list[LinkFrame]:
        frames: list[LinkFrame] = []
        start = 0
        while True:
            end = data.find(b"\0", start)
            chunk = data[start:] if end < 0 else data[start:end]
            if not self._skipping:
                self._buf += chunk
                if len(self._buf) > self.max_encoded:
                    self.oversize += 1
                    self._buf.clear()
                    self._skipping = True
            if end < 0:
                return frames
            if self._skipping:
                self._skipping = False
            elif self._buf:
                frame = self._decode(bytes(self._buf))
                if frame is not None:
                    frames.append(frame)
            self._buf.clear()
            start = end + 1

    def _decode(self, encoded: bytes) -> LinkFrame | None:
        try:
            plain = cobs.decode(encoded)
        except cobs.DecodeError:
            self.framing_errors += 1
            return None
        if len(plain) < 6:
            self.framing_errors += 1
            return None
        body, crc = plain[:-4], struct.unpack("<I", plain[-4:])[0]
        if zlib.crc32(body) != crc:
            self.crc_errors += 1
            return None
        return LinkFrame(body[0], body[1], body[2:])
