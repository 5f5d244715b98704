"""The codec round-trips every value and meets the documented extension byte layouts."""

import contextlib
import struct

import msgpack
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from astcom_client import Codec, CodecLimits, LimitExceeded, MalformedFrame, TimestampUs
from astcom_client.codec import DTYPE_CODES
from astcom_client.types import NUMERIC_DTYPES

codec = Codec()
ASTCOM = settings.get_profile("astcom")

DTYPES = ["bool", "i8", "i16", "i32", "i64", "u8", "u16", "u32", "u64", "f32", "f64"]

scalars = (st.none() | st.booleans() | st.integers(-(2**63), 2**64 - 1)
           | st.floats(allow_nan=False) | st.text(max_size=20) | st.binary(max_size=20))
values = st.recursive(scalars, lambda inner: st.lists(inner, max_size=4)
                      | st.dictionaries(st.text(max_size=8), inner, max_size=4), max_leaves=20)


@ASTCOM
@given(values)
def test_plain_values_round_trip(value: object) -> None:
    assert codec.decode(codec.encode(value)) == value


@ASTCOM
@given(st.sampled_from(DTYPES).flatmap(
    lambda d: hnp.arrays(NUMERIC_DTYPES[d], hnp.array_shapes(min_dims=0, max_dims=3, max_side=5))))
def test_numpy_arrays_round_trip_with_dtype_and_shape(arr: np.ndarray) -> None:
    out = codec.decode(codec.encode(arr))
    assert out.dtype == arr.dtype and out.shape == arr.shape
    np.testing.assert_array_equal(out, arr)


def test_ndarray_extension_has_the_documented_layout() -> None:
    arr = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])
    ext = msgpack.unpackb(codec.encode(arr), ext_hook=lambda code, data: (code, data))
    code, data = ext
    assert code == 1
    # u8 dtype code, u8 ndim, u16 zero, ndim x u32 sizes, padded to 8 bytes, then the values
    header = struct.pack("<BBHII", DTYPE_CODES["f64"], 2, 0, 2, 3) + b"\0" * 4
    assert data == header + arr.astype("<f8").tobytes()
    assert DTYPE_CODES["f64"] == 10


def test_ndarray_header_padding_keeps_elements_8_byte_aligned() -> None:
    arr = np.arange(3.0)
    _, data = msgpack.unpackb(codec.encode(arr), ext_hook=lambda code, data: (code, data))
    assert len(data) == 8 + 24  # 4 + 4 bytes of header, no padding needed
    out = codec.decode(codec.encode(np.arange(6.0).reshape(1, 2, 3)))
    assert out.flags.aligned


def test_arrays_are_decoded_without_copying() -> None:
    out = codec.decode(codec.encode(np.arange(1000.0)))
    assert not out.flags.owndata and not out.flags.writeable
    base = out
    while isinstance(base, np.ndarray):
        base = base.base
    assert isinstance(base, bytes)  # a view on the received frame's bytes


def test_big_endian_arrays_are_sent_little_endian() -> None:
    arr = np.arange(4, dtype=">i4")
    out = codec.decode(codec.encode(arr))
    assert out.dtype == np.dtype("<i4")
    np.testing.assert_array_equal(out, arr)


def test_timestamp_extension_is_int64_little_endian_microseconds() -> None:
    frame = codec.encode(TimestampUs(-5))
    assert frame == b"\xd7\x02" + struct.pack("<q", -5)
    assert codec.decode(frame) == TimestampUs(-5)


def test_numpy_scalars_become_plain_numbers() -> None:
    assert codec.decode(codec.encode([np.float64(1.5), np.int16(-3), np.bool_(True)])) == [1.5, -3, True]


def test_object_arrays_cannot_be_sent() -> None:
    with pytest.raises(TypeError):
        codec.encode(np.array([object()]))


def test_trailing_bytes_after_the_value_are_refused() -> None:
    with pytest.raises(MalformedFrame, match="extra"):
        codec.decode(msgpack.packb(1) + b"\x00")


def test_truncated_frames_are_refused() -> None:
    with pytest.raises(MalformedFrame, match="truncated"):
        codec.decode(msgpack.packb([1, 2, 3])[:-1])


def test_nesting_deeper_than_the_limit_is_refused() -> None:
    small = Codec(CodecLimits(max_depth=4))
    assert small.decode(msgpack.packb([[[1]]])) == [[[1]]]
    with pytest.raises(LimitExceeded, match="deeper"):
        small.decode(msgpack.packb([[[[[1]]]]]))


def test_arrays_longer_than_the_limit_are_refused() -> None:
    small = Codec(CodecLimits(max_array_len=10))
    with pytest.raises(LimitExceeded):
        small.decode(msgpack.packb(list(range(11))))
    with pytest.raises(LimitExceeded):
        small.decode(codec.encode(np.zeros(11)))


def test_frames_larger_than_the_limit_are_refused() -> None:
    small = Codec(CodecLimits(max_frame_bytes=100))
    with pytest.raises(LimitExceeded):
        small.decode(msgpack.packb(b"x" * 200))


@pytest.mark.parametrize("data", [
    b"\x63\x01\x00\x00",                                     # unknown dtype code 99
    struct.pack("<BBHI", 10, 1, 0, 4) + b"\x00" * 8,         # 4 f64 announced, 1 given
    struct.pack("<BBH", 10, 9, 0),                           # 9 dimensions
    b"\x00",                                                 # shorter than the header
    struct.pack("<BBHI", 0, 1, 0, 1) + b"\x02" + b"\0" * 0,  # bool byte other than 0/1
])
def test_malformed_array_extensions_are_refused(data: bytes) -> None:
    with pytest.raises(MalformedFrame):
        codec.decode(msgpack.packb(msgpack.ExtType(1, data)))


def test_unknown_extension_types_are_refused() -> None:
    with pytest.raises(MalformedFrame, match="extension"):
        codec.decode(msgpack.packb(msgpack.ExtType(9, b"abc")))


@ASTCOM
@given(st.binary(max_size=200))
def test_garbage_bytes_raise_only_documented_errors(data: bytes) -> None:
    with contextlib.suppress(MalformedFrame, LimitExceeded):
        codec.decode(data)
