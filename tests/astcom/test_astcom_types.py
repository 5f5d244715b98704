"""Type names parse to specs, and values are checked and coerced against them."""

import numpy as np
import pytest

from astcom_client import InvalidValue, parse_type


@pytest.mark.parametrize("text", ["bool", "i8", "i16", "i32", "i64", "u8", "u16", "u32", "u64",
                                  "f32", "f64", "str", "bytes", "f64[3]", "u8[2,3]", "f64[]",
                                  "{lat_deg:f64,lon_deg:f64}", "{a:{b:i32[2]},c:str}"])
def test_type_names_round_trip_through_the_parser(text: str) -> None:
    assert parse_type(text).name == text


@pytest.mark.parametrize("text", ["f65", "str[3]", "f64[0]", "f64[-1]", "{a f64}", "{a:f64",
                                  "{a:f64,a:i8}", "f64[3]x", ""])
def test_bad_type_names_are_refused_with_what_is_expected(text: str) -> None:
    with pytest.raises(InvalidValue):
        parse_type(text)


@pytest.mark.parametrize(("type_name", "value"), [
    ("u8", 256), ("u8", -1), ("i8", 128), ("i64", 2**63), ("u64", -1), ("i32", 1.5),
    ("f64", "1.0"), ("bool", 2), ("str", b"x"), ("bytes", "x"), ("f32", 1e39), ("i16", True),
])
def test_values_outside_their_type_are_refused(type_name: str, value: object) -> None:
    with pytest.raises(InvalidValue):
        parse_type(type_name).coerce(value)


def test_integer_bounds_follow_numpy_iinfo() -> None:
    for name, dtype in [("i8", np.int8), ("u16", np.uint16), ("i64", np.int64), ("u64", np.uint64)]:
        info = np.iinfo(dtype)
        spec = parse_type(name)
        assert spec.coerce(int(info.max)) == info.max
        assert spec.coerce(int(info.min)) == info.min


def test_fixed_arrays_check_their_shape_and_cast_their_elements() -> None:
    spec = parse_type("i16[3]")
    out = spec.coerce([1, 2.0, 3])
    assert out.dtype == np.int16 and out.tolist() == [1, 2, 3]
    with pytest.raises(InvalidValue, match="shape"):
        spec.coerce([1, 2])
    with pytest.raises(InvalidValue, match="range"):
        spec.coerce([1, 2, 40000])
    with pytest.raises(InvalidValue, match="integer"):
        spec.coerce([1, 2, 3.5])


def test_variable_arrays_take_any_length_of_one_dimension() -> None:
    spec = parse_type("f64[]")
    assert spec.coerce(range(5)).tolist() == [0.0, 1.0, 2.0, 3.0, 4.0]
    assert spec.coerce([]).shape == (0,)
    with pytest.raises(InvalidValue):
        spec.coerce([[1.0]])


def test_structs_need_exactly_their_fields() -> None:
    spec = parse_type("{lat_deg:f64,n:u8}")
    assert spec.coerce({"lat_deg": 1, "n": 2}) == {"lat_deg": 1.0, "n": 2}
    with pytest.raises(InvalidValue, match="fields"):
        spec.coerce({"lat_deg": 1.0})
    with pytest.raises(InvalidValue, match="n"):
        spec.coerce({"lat_deg": 1.0, "n": 300})


def test_stream_columns_count_scalars_and_fixed_array_elements_only() -> None:
    assert parse_type("f64").n_columns == 1
    assert parse_type("f32[2,3]").n_columns == 6
    assert parse_type("f64[]").n_columns == 0
    assert parse_type("str").n_columns == 0
