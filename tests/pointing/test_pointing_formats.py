"""TPOINT and CSV formats: the AuxTel file, round trips, and errors that name the line."""

from __future__ import annotations

import io

import numpy as np
import pytest

from pointing_model import (
    DataFormatError,
    PointingRun,
    RunParameters,
    load_run,
    load_tpoint,
    read_csv,
    read_tpoint,
    write_tpoint,
)


def test_auxtel_file_is_read_as_written(auxtel_path):
    run = load_tpoint(auxtel_path)
    assert len(run) == 54
    assert run.caption.startswith("LSST Auxiliary Telescope")
    assert run.options == ("ALTAZ", "ROTNL")
    assert run.parameters.latitude_deg == pytest.approx(-(30 + 14 / 60 + 40.3 / 3600), abs=1e-12)
    assert run.obs_az_deg[0] == 10.5802950 and run.enc_el_deg[-1] == 49.9735372
    assert run.aux[0] == (0.4402639,)  # the rotator column
    assert run.comments[0] == "[0026] AT_O_20220407_000160"
    assert run.line_numbers[0] == 5 and run.line_numbers[-1] == 58


def test_write_then_read_gives_the_same_run_and_parameters():
    params = RunParameters(-30.2445278, (2022, 4, 6), 10.5, 743.2, 2663.0, 0.35, 0.65, 0.0065)
    run = PointingRun(np.array([10.5, 359.99]), np.array([37.4, 80.0]),
                      np.array([-349.45, 0.01]), np.array([37.5, 80.1]), params,
                      "caption", ("ALTAZ", "ROTNL"), ((1.5,), (2.5,)), ("a star", ""))
    buf = io.StringIO()
    write_tpoint(run, buf)
    back = read_tpoint(io.StringIO(buf.getvalue()), "mem")
    for name in ("obs_az_deg", "obs_el_deg", "enc_az_deg", "enc_el_deg"):
        np.testing.assert_allclose(getattr(back, name), getattr(run, name), atol=1e-7)
    assert back.parameters.date == (2022, 4, 6)
    assert back.parameters.latitude_deg == pytest.approx(params.latitude_deg, abs=0.05 / 3600)
    assert (back.parameters.temperature_c, back.parameters.pressure_hpa) == (10.5, 743.2)
    assert back.parameters.lapse_rate_k_m == 0.0065
    assert back.aux == ((1.5,), (2.5,)) and back.comments == ("a star", "")


def test_small_negative_latitude_keeps_its_sign():
    buf = io.StringIO()
    write_tpoint(PointingRun([1.0], [40.0], [1.0], [40.0], RunParameters(-0.5)), buf)
    assert "-00 30 00.0" in buf.getvalue()
    assert read_tpoint(io.StringIO(buf.getvalue())).parameters.latitude_deg == -0.5


def test_comments_blank_lines_and_text_after_end_are_ignored():
    text = ("! written by hand\nCaption\n\n: ALTAZ\n! latitude next\n+45 00 00\n"
            "10 40 10.01 40.02 ; first\n\n! a comment\n20 50 20.01 50.02\nEND\ngarbage here\n")
    run = read_tpoint(io.StringIO(text), "hand.dat")
    assert len(run) == 2 and run.line_numbers == (7, 10)


HEADER = "Caption\n: ALTAZ\n-30 14 40.3\n"


@pytest.mark.parametrize(("text", "line_no", "fragment"), [
    ("Caption\n-30 14 40.3\n1 2 3 4\n", 2, "ALTAZ"),
    ("Caption\n: ALTAZ\n-30 14\n", 3, "2 fields"),
    ("Caption\n: ALTAZ\n-30 14 4x\n", 3, "non-numeric"),
    ("Caption\n: ALTAZ\n-30 75 0\n", 3, "latitude out of range"),
    ("Caption\n: ALTAZ\n-30 14 40.3 2022 13 6\n", 3, "date"),
    (HEADER + "10 40 10.01\n", 4, "3 numeric field"),
    (HEADER + "10 40 10.01 40.02\n10 40 abc 40.02\n", 5, "'abc' is not a number"),
    (HEADER + "10 95 10.01 40.02\n", 4, "E_obs = 95"),
    (HEADER + "10 40 10.01 40.02\n: ROTNL\n", 5, "option line after"),
    (HEADER, 4, "no observation records"),
    ("Caption\n: ALTAZ\n", 3, "before the run-parameters"),
])
def test_malformed_tpoint_file_error_names_the_line_and_what_was_expected(text, line_no, fragment):
    with pytest.raises(DataFormatError) as info:
        read_tpoint(io.StringIO(text), "bad.dat")
    err = info.value
    assert err.line_no == line_no
    assert str(err).startswith(f"bad.dat:{line_no}: ")
    assert fragment in str(err) and "expected" in str(err)


def test_empty_tpoint_file_says_a_caption_is_expected():
    with pytest.raises(DataFormatError, match="empty.*caption"):
        read_tpoint(io.StringIO("! only a comment\n"), "empty.dat")


def test_csv_with_observed_altaz_rows_is_read():
    text = ("# latitude_deg = -30.2445\nutc,obs_az_deg,obs_el_deg,enc_az_deg,enc_el_deg\n"
            "2022-04-07T00:01:00,10.5,37.4,10.49,37.5\n2022-04-07T00:02:00,200,50,199.98,50.1\n")
    run = read_csv(io.StringIO(text), "run.csv")
    assert len(run) == 2 and run.parameters.latitude_deg == -30.2445
    np.testing.assert_allclose(run.enc_el_deg, [37.5, 50.1])
    assert run.line_numbers == (3, 4)


def test_csv_radec_rows_go_through_the_given_converter():
    calls = []

    def convert(utcs, ra, dec):
        calls.append((list(utcs), ra.tolist(), dec.tolist()))
        return ra + 1.0, dec - 1.0  # a stand-in for the astronomy, recorded for the check

    text = ("utc,ra_deg,dec_deg,obs_az_deg,obs_el_deg,enc_az_deg,enc_el_deg\n"
            "2022-04-07T00:01:00,,,10,40,10.01,40.02\n2022-04-07T00:02:00,100,45,,,101.1,44.1\n")
    run = read_csv(io.StringIO(text), "mix.csv", radec_to_altaz=convert)
    assert calls == [(["2022-04-07T00:02:00"], [100.0], [45.0])]
    np.testing.assert_allclose(run.obs_az_deg, [10.0, 101.0])
    np.testing.assert_allclose(run.obs_el_deg, [40.0, 44.0])


@pytest.mark.parametrize(("text", "line_no", "fragment"), [
    ("az,el\n1,2\n", 1, "header has columns az, el"),
    ("obs_az_deg,obs_el_deg,enc_az_deg,enc_el_deg\n1,2,x,4\n", 2, "'x' is not a number"),
    ("utc,ra_deg,dec_deg,obs_az_deg,obs_el_deg,enc_az_deg,enc_el_deg\n,,,,,1,2\n", 2,
     "neither"),
    ("utc,ra_deg,dec_deg,enc_az_deg,enc_el_deg\n2022-04-07T00:00:00,10,20,1,2\n", 2, "RA/Dec"),
    ("obs_az_deg,obs_el_deg,enc_az_deg,enc_el_deg\n1,2,3,400\n", 2, "enc_el_deg"),
    ("obs_az_deg,obs_el_deg,enc_az_deg,enc_el_deg\n", 2, "no data rows"),
])
def test_malformed_csv_error_names_the_line(text, line_no, fragment):
    with pytest.raises(DataFormatError) as info:
        read_csv(io.StringIO(text), "bad.csv")
    assert info.value.line_no == line_no
    assert str(info.value).startswith(f"bad.csv:{line_no}: ") and fragment in str(info.value)


def test_load_run_picks_the_format_by_suffix(tmp_path):
    (tmp_path / "r.csv").write_text("obs_az_deg,obs_el_deg,enc_az_deg,enc_el_deg\n1,40,1,40\n")
    (tmp_path / "r.dat").write_text(HEADER + "1 40 1 40\n")
    assert len(load_run(tmp_path / "r.csv")) == 1 and len(load_run(tmp_path / "r.dat")) == 1
