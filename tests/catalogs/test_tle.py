"""TLE and OMM reading: bundled sets against sgp4's own parser, layout/checksum errors, epoch age."""

from __future__ import annotations

import math
import re
import warnings
from datetime import timedelta
from pathlib import Path

import numpy as np
import pytest
from sgp4.api import Satrec
from sgp4.conveniences import sat_epoch_datetime

from catalogs import (
    TEMPLATE_LINE1,
    TEMPLATE_LINE2,
    OmmFormatError,
    TleChecksumError,
    TleEpochWarning,
    TleFormatError,
    UnknownSampleSet,
    UnknownSatellite,
    check_epoch,
    load_tle_file,
    parse_omm_json,
    parse_tle_text,
    sample_tle_path,
    sample_tle_sets,
    select_satellite,
    tle_checksum,
)

TLE_SETS = ["stations", "visual"]
REV_DAY_TO_RAD_MIN = 2.0 * math.pi / 1440.0
ONE_METRE_KM = 1e-3
ONE_MICROSECOND_S = 1e-6

ISS_NAME = "ISS (ZARYA)"
ISS_L1 = "1 25544U 98067A   24138.99590321  .00027700  00000+0  46629-3 0  9991"
ISS_L2 = "2 25544  51.6390 105.0245 0003368 179.7401 290.4240 15.51492720453865"


def _with_checksum(line: str) -> str:
    return line[:68] + str(tle_checksum(line))


def test_sample_sets_are_listed_and_unknown_names_list_the_choices():
    assert {"stations", "visual", "stations-omm"} <= set(sample_tle_sets())
    with pytest.raises(UnknownSampleSet, match="available: stations"):
        sample_tle_path("nope")


def test_stations_set_holds_the_iss_and_the_chinese_station():
    names = {r.name for r in load_tle_file(sample_tle_path("stations"))}
    assert {ISS_NAME, "CSS (TIANHE)"} <= names


@pytest.mark.parametrize("name", TLE_SETS)
def test_bundled_tle_fields_agree_with_sgp4_twoline2rv(name):
    records = load_tle_file(sample_tle_path(name))
    assert len(records) >= 5
    for rec in records:
        el = rec.elements
        sat = Satrec.twoline2rv(rec.line1, rec.line2)
        assert el.satnum == sat.satnum
        assert el.classification == sat.classification
        assert el.intldesg == sat.intldesg
        assert el.ephemeris_type == sat.ephtype
        assert el.element_number == sat.elnum
        assert el.rev_number == sat.revnum
        epoch_diff_s = (el.epoch_utc - sat_epoch_datetime(sat)).total_seconds()
        assert abs(epoch_diff_s) <= ONE_MICROSECOND_S
        assert math.radians(el.inclination_deg) == pytest.approx(sat.inclo, abs=1e-12)
        assert math.radians(el.raan_deg) == pytest.approx(sat.nodeo, abs=1e-12)
        assert math.radians(el.arg_perigee_deg) == pytest.approx(sat.argpo, abs=1e-12)
        assert math.radians(el.mean_anomaly_deg) == pytest.approx(sat.mo, abs=1e-12)
        assert el.eccentricity == pytest.approx(sat.ecco, abs=1e-12)
        assert el.mean_motion_rev_day * REV_DAY_TO_RAD_MIN == pytest.approx(sat.no_kozai, rel=1e-12)
        assert el.bstar_per_earth_radius == pytest.approx(sat.bstar, rel=1e-12, abs=1e-15)
        assert el.ndot_rev_day2 * REV_DAY_TO_RAD_MIN / 1440.0 == pytest.approx(sat.ndot, rel=1e-9,
                                                                              abs=1e-20)


def test_two_line_sets_without_names_and_3le_zero_prefix_are_read():
    two = parse_tle_text(f"{ISS_L1}\n{ISS_L2}\n")
    three = parse_tle_text(f"0 {ISS_NAME}\n{ISS_L1}\n{ISS_L2}\n")
    assert two[0].name == "25544" and three[0].name == ISS_NAME
    assert two[0].line1 == three[0].line1 == ISS_L1


def test_crlf_blank_lines_and_trailing_spaces_are_tolerated():
    text = f"\r\n{ISS_NAME}   \r\n{ISS_L1}  \r\n{ISS_L2}\r\n\r\n"
    assert parse_tle_text(text)[0].line2 == ISS_L2


def test_wrong_checksum_names_file_line_and_expected_digit():
    bad = ISS_L1[:68] + "0"
    with pytest.raises(TleChecksumError) as info:
        parse_tle_text(f"{ISS_NAME}\n{bad}\n{ISS_L2}\n", source="iss.tle")
    err = info.value
    assert isinstance(err, ValueError)
    assert (err.source, err.line_number, err.column) == ("iss.tle", 2, 69)
    assert "iss.tle, line 2" in str(err) and "is 1 but column 69 says 0" in str(err)


def test_layout_error_shows_the_template_above_the_offending_line_with_a_caret():
    shifted = _with_checksum(ISS_L2[:8] + " " + ISS_L2[8:67])  # inclination moved right by one
    with pytest.raises(TleFormatError) as info:
        parse_tle_text(f"{ISS_NAME}\n{ISS_L1}\n{shifted}\n", source="iss.tle")
    lines = str(info.value).splitlines()
    assert lines[0] == ("iss.tle, line 3: column 12 of TLE line 2 is '1', "
                        "expected inclination's decimal point")
    t, g = lines.index("  " + TEMPLATE_LINE2), lines.index("  " + shifted)
    assert t < g
    assert lines[g + 1] == "  " + " " * 11 + "^"


@pytest.mark.parametrize(("mutate", "col"), [
    (lambda s: s[:23] + "," + s[24:], 24),   # epoch decimal point
    (lambda s: s[:7] + "X" + s[8:], 8),      # classification
    (lambda s: s[:52] + "x" + s[53:], 53),   # blank before BSTAR
])
def test_each_line1_column_rule_reports_its_column(mutate, col):
    bad = _with_checksum(mutate(ISS_L1))
    with pytest.raises(TleFormatError) as info:
        parse_tle_text(f"{bad}\n{ISS_L2}\n")
    assert info.value.column == col
    assert TEMPLATE_LINE1 in str(info.value)


def test_templates_match_the_column_rules_of_a_real_tle():
    assert len(TEMPLATE_LINE1) == len(TEMPLATE_LINE2) == 69
    for template, line in ((TEMPLATE_LINE1, ISS_L1), (TEMPLATE_LINE2, ISS_L2)):
        for t, c in zip(template, line, strict=True):
            if t in " .":
                assert c == t


def test_short_line_is_reported_with_its_length():
    with pytest.raises(TleFormatError, match="has 60 columns, expected 69"):
        parse_tle_text(f"{ISS_L1[:60]}\n{ISS_L2}\n")


def test_satellite_number_mismatch_between_lines_is_reported():
    other = _with_checksum(ISS_L2[:2] + "25545" + ISS_L2[7:])
    with pytest.raises(TleFormatError, match="differs from line 1's '25544'"):
        parse_tle_text(f"{ISS_L1}\n{other}\n")


def test_name_without_element_lines_is_reported():
    with pytest.raises(TleFormatError, match="line 5: expected TLE line 1 after the name 'NAME ONLY'"):
        parse_tle_text(f"{ISS_NAME}\n{ISS_L1}\n{ISS_L2}\nNAME ONLY\nANOTHER NAME\n")


def test_file_errors_name_the_file(tmp_path):
    path = tmp_path / "broken.tle"
    path.write_text(f"{ISS_NAME}\n{ISS_L1[:68]}5\n{ISS_L2}\n")
    with pytest.raises(TleChecksumError, match="broken.tle, line 2"):
        load_tle_file(path)


def test_omm_json_gives_the_same_positions_as_the_tle_within_a_metre():
    tles = {r.satnum: r for r in load_tle_file(sample_tle_path("stations"))}
    omms = load_tle_file(sample_tle_path("stations-omm"))
    assert len(omms) == len(tles)
    minutes = np.array([0.0, 45.0, 90.0, 720.0, 1440.0])
    for omm in omms:
        tle = tles[omm.satnum]
        assert omm.name == tle.name and omm.omm is not None
        assert abs((omm.epoch_utc - tle.epoch_utc).total_seconds()) < ONE_MICROSECOND_S
        s1, s2 = tle.satrec(), omm.satrec()
        for t in minutes:
            e1, r1, _ = s1.sgp4_tsince(t)
            e2, r2, _ = s2.sgp4_tsince(t)
            assert e1 == e2 == 0
            assert math.dist(r1, r2) < ONE_METRE_KM


def test_omm_with_string_values_and_z_epoch_is_accepted():
    text = ('{"OBJECT_NAME": "ISS (ZARYA)", "OBJECT_ID": "1998-067A", '
            '"EPOCH": "2024-05-17T23:54:06.037344Z", "MEAN_MOTION": "15.5149272", '
            '"ECCENTRICITY": "0.0003368", "INCLINATION": "51.639", "RA_OF_ASC_NODE": "105.0245", '
            '"ARG_OF_PERICENTER": "179.7401", "MEAN_ANOMALY": "290.424", "NORAD_CAT_ID": "25544", '
            '"BSTAR": "0.00046629", "MEAN_MOTION_DOT": "0.000277", "MEAN_MOTION_DDOT": "0"}')
    (rec,) = parse_omm_json(text)
    e1, r1, _ = rec.satrec().sgp4_tsince(60.0)
    e2, r2, _ = Satrec.twoline2rv(ISS_L1, ISS_L2).sgp4_tsince(60.0)
    assert math.dist(r1, r2) < ONE_METRE_KM


@pytest.mark.parametrize(("change", "message"), [
    ({"EPOCH": "17 May 2024"}, "EPOCH is '17 May 2024', expected YYYY-MM-DD"),
    ({"MEAN_MOTION": "fast"}, "MEAN_MOTION is 'fast', expected a number"),
    ({"NORAD_CAT_ID": "25544.5"}, "NORAD_CAT_ID is '25544.5', expected an integer"),
    ({"INCLINATION": None}, "missing field(s) INCLINATION"),
])
def test_bad_omm_record_names_the_record_and_field(change, message):
    import json

    records = json.loads(sample_tle_path("stations-omm").read_text())[:2]
    records[1].update(change)
    if change.get("INCLINATION", 0) is None:
        del records[1]["INCLINATION"]
    with pytest.raises(OmmFormatError) as info:
        parse_omm_json(json.dumps(records), source="x.json")
    assert str(info.value).startswith("x.json, OMM record 1: ")
    assert message in str(info.value)


def test_epoch_check_warns_beyond_14_days_either_side_and_not_within():
    iss = select_satellite(load_tle_file(sample_tle_path("stations")), ISS_NAME)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert check_epoch(iss, iss.epoch_utc + timedelta(days=13.9)) == pytest.approx(13.9)
        check_epoch(iss, iss.epoch_utc - timedelta(days=13.9))
    with pytest.warns(TleEpochWarning, match="15.0 days after the TLE epoch 2024-05-17"):
        check_epoch(iss, iss.epoch_utc + timedelta(days=15))
    with pytest.warns(TleEpochWarning, match="before"):
        check_epoch(iss, iss.epoch_utc - timedelta(days=15))


def test_epoch_check_takes_naive_datetimes_as_utc():
    iss = load_tle_file(sample_tle_path("stations"))[0]
    naive = iss.epoch_utc.replace(tzinfo=None) + timedelta(hours=6)
    assert check_epoch(iss, naive) == pytest.approx(0.25)


def test_select_satellite_by_name_or_number_and_suggests_on_miss():
    records = load_tle_file(sample_tle_path("visual"))
    assert select_satellite(records, "hst").satnum == 20580
    assert select_satellite(records, "20580").name == "HST"
    assert select_satellite(records, "AJISAI").name == "AJISAI (EGS)"  # NAME of NAME (ALIAS)
    with pytest.raises(UnknownSatellite, match=r"did you mean: AJISAI \(EGS\)"):
        select_satellite(records, "AJISAI (EG)")


@pytest.mark.parametrize(("query", "name"), [
    ("ISS", "ISS (ZARYA)"), ("zarya", "ISS (ZARYA)"), (" Nauka ", "ISS (NAUKA)"),
    ("css", "CSS (TIANHE)"), ("Wentian", "CSS (WENTIAN)"), ("ISS DEB", "ISS DEB"),
])
def test_a_short_celestrak_name_finds_the_station_s_oldest_object(query, name):
    records = load_tle_file(sample_tle_path("stations"))
    chosen = select_satellite(records, query)
    assert chosen.name == name
    # the rule: of the records answering to that short name, the lowest catalog number
    same = [r for r in records if r.name == name]
    assert chosen.satnum == min(r.satnum for r in same)
    if query.strip().lower() in ("iss", "css"):
        modules = [r for r in records if r.name.startswith(query.upper() + " (")]
        assert len(modules) >= 2 and chosen.satnum == min(r.satnum for r in modules)


def test_an_element_file_that_is_no_file_says_what_it_is(tmp_path, monkeypatch):
    import os

    import catalogs.tle
    from catalogs import ElementFileError, read_element_text

    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)  # nobody writes: opening it must not block
    binary = tmp_path / "bin.tle"
    binary.write_bytes(b"1 25544U \xff\xfe\x00")
    for path, words in ((Path("/dev/zero"), "is a character device, not a regular file"),
                        (fifo, "is a FIFO, not a regular file"),
                        (tmp_path, "is a directory, not a regular file"),
                        (tmp_path / "none.tle", "none.tle: no such file"),
                        (binary, "is not text (byte 9 is 0xFF)")):
        with pytest.raises(ElementFileError, match=re.escape(words)):
            read_element_text(path)
        with pytest.raises(ElementFileError, match=re.escape(words)):
            load_tle_file(path)
    big = tmp_path / "big.tle"
    big.write_text("x" * 200)
    monkeypatch.setattr(catalogs.tle, "MAX_ELEMENT_FILE_BYTES", 100)
    with pytest.raises(ElementFileError, match="holds 200 bytes, more than the 100"):
        read_element_text(big)
