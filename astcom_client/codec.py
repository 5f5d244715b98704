"""Encode and decode ASTCom frames with msgpack and two extension types.

Extension types (byte layouts in docs/astcom-protocol.md):

* ``EXT_NDARRAY`` (1): typed numeric array. Header: u8 dtype code, u8 ndim, u16 zero,
  ndim × u32 little-endian sizes, zero padding up to a multiple of 8 bytes; then the
  elements, C order, little-endian. Decoded without copying by ``numpy.frombuffer``
  (the array is read-only and aligned, because the header is padded to 8 bytes).
* ``EXT_TIMESTAMP_US`` (2): i64 little-endian, microseconds since 1970-01-01 UTC.

Security limits are enforced by msgpack's C unpacker (string, binary, array, map and
extension lengths) and by a nesting-depth walk after decoding.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Any

import msgpack
import numpy as np

from .exceptions import LimitExceeded, MalformedFrame
from .types import NUMERIC_DTYPES

__all__ = [
    "DTYPE_CODES",
    "EXT_NDARRAY",
    "EXT_TIMESTAMP_US",
    "Codec",
    "CodecLimits",
    "TimestampUs",
]

EXT_NDARRAY = 1
EXT_TIMESTAMP_US = 2
DTYPE_CODES: dict[str, int] = {name: i for i, name in enumerate(NUMERIC_DTYPES)}
_DTYPE_BY_CODE: dict[int, np.dtype] = {i: NUMERIC_DTYPES[n] for n, i in DTYPE_CODES.items()}
_CODE_BY_DTYPE: dict[np.dtype, int] = {NUMERIC_DTYPES[n]: i for n, i in DTYPE_CODES.items()}
_MAX_NDIM = 8
_Q = struct.Struct("<q")
_HEAD = struct.Struct("<BBH")
_SHAPES = [struct.Struct(f"<{n}I") for n in range(_MAX_NDIM + 1)]
_HEAD_BYTES = [(4 + 4 * n + 7) // 8 * 8 for n in range(_MAX_NDIM + 1)]


@dataclass(frozen=True)
class TimestampUs:
    """A point in time as integer microseconds since 1970-01-01 UTC (ext type 2)."""

    t_us: int


@dataclass(frozen=True)
class CodecLimits:
    """Security limits applied to every decoded frame."""

    max_frame_bytes: int = 1 << 20
    max_depth: int = 16
    max_array_len: int = 100_000  # msgpack array/map entries and ndarray elements
    max_str_bytes: int = 1 << 16


def _array_header(dtype_code: int, shape: tuple[int, ...]) -> bytes:
    head = struct.pack(f"<BBH{len(shape)}I", dtype_code, len(shape), 0, *shape)
    return head + b"\0" * (-len(head) % 8)


_HEADERS: dict[tuple[int, tuple[int, ...]], bytes] = {}


def encode_ndarray(arr: np.ndarray) -> msgpack.ExtType:
    """Return the EXT_NDARRAY for a numeric or bool numpy array."""
    code = _CODE_BY_DTYPE.get(arr.dtype)
    if code is None or not arr.flags.c_contiguous:
        dtype = arr.dtype.newbyteorder("<") if arr.dtype.byteorder == ">" else arr.dtype
        code = _CODE_BY_DTYPE.get(dtype)
        if code is None:
            raise TypeError(f"cannot send numpy arrays of dtype {arr.dtype}; use bool, ints or floats")
        arr = np.asarray(arr, dtype=_DTYPE_BY_CODE[code], order="C")  # keeps 0-d arrays 0-d
    if arr.ndim > _MAX_NDIM:
        raise TypeError(f"cannot send arrays of more than {_MAX_NDIM} dimensions")
    header = _HEADERS.get((code, arr.shape))
    if header is None:
        header = _array_header(code, arr.shape)
        if len(_HEADERS) >= 256:
            _HEADERS.clear()
        _HEADERS[(code, arr.shape)] = header
    return msgpack.ExtType(EXT_NDARRAY, b"".join((header, arr.data)))


def _default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return encode_ndarray(obj)
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, TimestampUs):
        return msgpack.ExtType(EXT_TIMESTAMP_US, _Q.pack(obj.t_us))
    raise TypeError(f"cannot encode {type(obj).__name__} in an ASTCom frame")


class Codec:
    """Turn python objects into msgpack frames and back, within `limits`."""

    def __init__(self, limits: CodecLimits | None = None) -> None:
        self.limits = limits or CodecLimits()
        self._packer = msgpack.Packer(default=_default, use_bin_type=True, autoreset=True)
        self._layouts: dict[bytes, tuple[np.dtype, tuple[int, ...], int, int]] = {}
        lim = self.limits
        self._unpack_kwargs = dict(
            raw=False,
            strict_map_key=True,
            ext_hook=self._ext_hook,
            max_str_len=lim.max_str_bytes,
            max_bin_len=lim.max_frame_bytes,
            max_array_len=lim.max_array_len,
            max_map_len=lim.max_array_len,
            max_ext_len=lim.max_frame_bytes,
        )

    def encode(self, obj: Any) -> bytes:
        """Return the msgpack bytes of `obj` (numpy arrays become EXT_NDARRAY)."""
        return self._packer.pack(obj)

    def decode(self, frame: bytes) -> Any:
        """Return the object in one frame; raise MalformedFrame or LimitExceeded."""
        if len(frame) > self.limits.max_frame_bytes:
            raise LimitExceeded(f"frame of {len(frame)} bytes exceeds the limit of "
                                f"{self.limits.max_frame_bytes} bytes")
        try:
            obj = msgpack.unpackb(frame, **self._unpack_kwargs)
        except msgpack.ExtraData as exc:
            raise MalformedFrame(f"frame holds {len(exc.extra)} extra bytes after its msgpack "
                                 "value (exactly one value per frame)") from None
        except (LimitExceeded, MalformedFrame):
            raise
        except msgpack.StackError:  # msgpack's own bound (1024 levels), far above max_depth
            raise LimitExceeded(f"frame nests deeper than {self.limits.max_depth} levels") from None
        except ValueError as exc:
            text = str(exc)
            # bin and ext may be as long as a whole frame: one over that limit runs past the
            # frame's end (spec §8: a length past the end is a truncated frame, 400)
            if "exceeds max_ext_len" in text or "exceeds max_bin_len" in text:
                raise MalformedFrame("frame ends inside a msgpack value: a bin or ext declares "
                                     "more bytes than the frame holds (truncated frame)") from None
            if "exceeds max" in text:
                raise LimitExceeded(f"frame exceeds a size limit: {text}") from None
            if "incomplete" in text or "truncated" in text.lower():
                raise MalformedFrame("frame ends inside a msgpack value: a value declares more "
                                     "bytes than the frame holds (truncated frame)") from None
            raise MalformedFrame(f"frame is not valid msgpack: {text}") from None
        except Exception as exc:  # msgpack raises several types for hostile bytes
            raise MalformedFrame(f"frame is not valid msgpack: {type(exc).__name__}: {exc}") from None
        if type(obj) is list or type(obj) is dict:
            _check_depth(obj, self.limits.max_depth, 1)
        return obj

    def _ext_hook(self, code: int, data: bytes) -> Any:
        if code == EXT_NDARRAY:
            return self._decode_ndarray(data)
        if code == EXT_TIMESTAMP_US:
            if len(data) != 8:
                raise MalformedFrame(f"timestamp extension holds {len(data)} bytes, expected 8")
            return TimestampUs(_Q.unpack(data)[0])
        raise MalformedFrame(f"unknown extension type {code}; known: 1 (ndarray), 2 (timestamp)")

    def _decode_ndarray(self, data: bytes) -> np.ndarray:
        # Stream packets repeat the same header; remember parsed headers (a bounded cache).
        if len(data) < 4 or data[1] > _MAX_NDIM:
            raise MalformedFrame("ndarray extension shorter than its header or of more than "
                                 f"{_MAX_NDIM} dimensions")
        key = data[:_HEAD_BYTES[data[1]]]
        layout = self._layouts.get(key)
        if layout is None:
            layout = self._parse_array_header(data)
            if len(self._layouts) >= 256:
                self._layouts.clear()
            self._layouts[key] = layout
        dtype, shape, count, head = layout
        if len(data) - head != count * dtype.itemsize:
            raise MalformedFrame(f"ndarray of shape {shape} and dtype {dtype} needs "
                                 f"{count * dtype.itemsize} bytes, got {len(data) - head}")
        arr = np.frombuffer(data, dtype=dtype, count=count, offset=head)
        if dtype.kind == "b" and count and arr.view(np.uint8).max() > 1:
            raise MalformedFrame("bool ndarray holds bytes other than 0 and 1")
        return arr if len(shape) == 1 else arr.reshape(shape)

    def _parse_array_header(self, data: bytes) -> tuple[np.dtype, tuple[int, ...], int, int]:
        if len(data) < 4:
            raise MalformedFrame("ndarray extension shorter than its 4-byte header")
        code, ndim, reserved = _HEAD.unpack_from(data)
        if reserved:
            raise MalformedFrame(f"ndarray header's reserved field is {reserved}; it must be 0")
        dtype = _DTYPE_BY_CODE.get(code)
        if dtype is None:
            raise MalformedFrame(f"ndarray dtype code {code} unknown; expected 0..{len(DTYPE_CODES) - 1}")
        if ndim > _MAX_NDIM:
            raise MalformedFrame(f"ndarray of {ndim} dimensions; at most {_MAX_NDIM}")
        head = _HEAD_BYTES[ndim]
        if len(data) < head:
            raise MalformedFrame("ndarray extension shorter than its shape header")
        shape = _SHAPES[ndim].unpack_from(data, 4)
        count = 1
        for size in shape:
            count *= size
        if count > self.limits.max_array_len:
            raise LimitExceeded(f"ndarray of {count} elements exceeds the limit of "
                                f"{self.limits.max_array_len}")
        return dtype, shape, count, head


def _check_depth(obj: list | dict, max_depth: int, depth: int) -> None:
    """Raise LimitExceeded when containers nest deeper than `max_depth` (recursion is bounded by it)."""
    if depth > max_depth:
        raise LimitExceeded(f"frame nests deeper than {max_depth} levels")
    for child in (obj.values() if type(obj) is dict else obj):
        if type(child) is list or type(child) is dict:
            _check_depth(child, max_depth, depth + 1)
