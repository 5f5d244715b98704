"""The Parameters of the Offset and TrackSatellite actions: text and JSON forms, refusals."""

from __future__ import annotations

import pytest

from virtualstar.alpaca.actions import offset_params, track_satellite_params
from virtualstar.alpaca.protocol import INVALID_VALUE, AlpacaError


@pytest.mark.parametrize(("text", "params"), [
    ("dec add 5", {"axis": "dec", "op": "add", "arcsec": 5.0}),
    ("RA -3.5", {"axis": "ra", "arcsec": -3.5}),
    ("path add 1.5s", {"axis": "path", "op": "add", "seconds": 1.5}),
    ("transverse rate 0.2", {"axis": "transverse", "op": "rate", "arcsec": 0.2}),
    ("all reset", {"axis": "all", "op": "reset"}),
    ('{"axis": "el", "op": "set", "arcsec": 30}', {"axis": "el", "op": "set", "arcsec": 30}),
])
def test_offset_parameters_in_text_or_json_become_the_vss_offset_command(text, params):
    assert offset_params(text) == params


@pytest.mark.parametrize("text", ["", "dec add", "dec add x", "dec add nan", "a b c d",
                                  '{"axis": 5}', '{"axis": "ra", "by": 1}', "[1, 2]",
                                  "{not json", "x" * 2000])
def test_malformed_offset_parameters_are_refused_with_the_expected_form(text):
    with pytest.raises(AlpacaError) as exc:
        offset_params(text)
    assert exc.value.number == INVALID_VALUE
    assert "expected" in str(exc.value) or "finite" in str(exc.value) \
        or "JSON" in str(exc.value) or "long" in str(exc.value)


def test_track_satellite_takes_the_tle_text_or_json_with_closed_loop():
    tle = "ISS\n1 ...\n2 ..."
    assert track_satellite_params(tle) == {"tle": tle}
    assert track_satellite_params('{"tle": "X", "sat": "ISS", "closed_loop": true}') == \
        {"tle": "X", "sat": "ISS", "closed_loop": True}
    for bad in ("", '{"tle": ""}', '{"tle": "X", "closed_loop": "yes"}', '{"x": 1}'):
        with pytest.raises(AlpacaError):
            track_satellite_params(bad)
