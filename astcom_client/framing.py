"""Cut a TCP byte stream into ASTCom frames: a 4-byte big-endian length, then the frame."""

from __future__ import annotations

import struct

from .exceptions import LimitExceeded

__all__ = ["FrameReader", "frame_bytes"]

_LEN = struct.Struct(">I")
HEADER_BYTES = _LEN.size


def frame_bytes(payload: bytes) -> bytes:
    """Return `payload` with its length prefix."""
    return _LEN.pack(len(payload)) + payload


class FrameReader:
    """Accumulate received bytes and return complete frames, refusing oversized ones."""

    def __init__(self, max_frame_bytes: int) -> None:
        self.max_frame_bytes = max_frame_bytes
        self._buffer = bytearray()

    def feed(self, data: bytes) -> list[bytes]:
        """Add received bytes; return the frames now complete; raise LimitExceeded."""
        self._buffer += data
        frames: list[bytes] = []
        buf = self._buffer
        start = 0
        while len(buf) - start >= HEADER_BYTES:
            (size,) = _LEN.unpack_from(buf, start)
            if size > self.max_frame_bytes:
                raise LimitExceeded(f"frame of {size} bytes announced; the limit is "
                                    f"{self.max_frame_bytes} bytes")
            end = start + HEADER_BYTES + size
            if len(buf) < end:
                break
            frames.append(bytes(buf[start + HEADER_BYTES:end]))
            start = end
        if start:
            del buf[:start]
        return frames

    @property
    def buffered(self) -> int:
        return len(self._buffer)
