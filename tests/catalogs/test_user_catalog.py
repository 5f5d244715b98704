"""User star catalogs from CSV: coordinate forms, merging with the bundled stars, errors."""

from __future__ import annotations

import pytest

from catalogs import StarCsvError, bright_stars, load_star_csv, read_star_csv_text

ONE_MAS_DEG = 1.0 / 3_600_000.0

M1_RA_DEG = 15.0 * (5 + 34 / 60 + 31.94 / 3600)  # 05h34m31.94s
M1_DEC_DEG = 22 + 0 / 60 + 52.2 / 3600           # +22d00m52.2s


@pytest.mark.parametrize(("ra", "dec"), [
    ("05h34m31.94s", "+22d00m52.2s"),
    ("05:34:31.94", "+22:00:52.2"),
    ("5 34 31.94", "22 00 52.2"),
    (f"{M1_RA_DEG:.9f}", f"{M1_DEC_DEG:.9f}"),
])
def test_ra_dec_in_degrees_or_sexagesimal_give_the_same_position(ra, dec):
    (star,) = read_star_csv_text(f'name,ra,dec\nCrab,"{ra}","{dec}"\n')
    assert abs(star.ra_deg - M1_RA_DEG) < ONE_MAS_DEG
    assert abs(star.dec_deg - M1_DEC_DEG) < ONE_MAS_DEG


def test_negative_sexagesimal_declination_keeps_its_sign():
    (star,) = read_star_csv_text("name,ra,dec\nX,12:00:00,-00:30:00\n")
    assert star.dec_deg == pytest.approx(-0.5, abs=ONE_MAS_DEG)


def test_optional_columns_and_their_short_aliases_are_read():
    text = ("# my targets\nname,ra,dec,pmra,pmdec,plx,rv,vmag,epoch\n"
            "Barnard,269.452,4.6934,-798.58,10328.12,548.31,-110.6,9.5,1991.25\n")
    (star,) = read_star_csv_text(text)
    assert (star.pm_ra_cosdec_mas_yr, star.pm_dec_mas_yr, star.parallax_mas) == (
        -798.58, 10328.12, 548.31)
    assert star.rv_km_s == -110.6 and star.rv_known and star.vmag == 9.5
    assert star.epoch_jyear == 1991.25


def test_defaults_are_zero_motion_at_j2000():
    (star,) = read_star_csv_text("name,ra,dec\nX,10,20\n")
    assert (star.pm_ra_cosdec_mas_yr, star.parallax_mas, star.rv_known) == (0.0, 0.0, False)
    assert star.epoch_jyear == 2000.0


def test_user_catalog_merges_with_bundled_stars_for_lookup(tmp_path):
    path = tmp_path / "mine.csv"
    path.write_text("name,ra,dec\nCrab Nebula,05h34m31.94s,+22d00m52.2s\n")
    cat = bright_stars().merged(load_star_csv(path))
    assert len(cat) == len(bright_stars()) + 1
    assert cat.lookup("crab nebula").ra_deg == pytest.approx(M1_RA_DEG)
    assert cat.lookup("Vega").hip == 91262
    with pytest.raises(KeyError, match="did you mean: Crab Nebula"):
        cat.lookup("Crab Nebul")


def test_user_star_with_a_bundled_name_overrides_it():
    user = read_star_csv_text("name,ra,dec\nVega,1.0,2.0\n")
    assert bright_stars().merged(user).lookup("Vega").ra_deg == 1.0


@pytest.mark.parametrize(("text", "message"), [
    ("name,ra\nX,10\n", "line 1: header lacks column(s) dec"),
    ("name,ra,dec\nX,10,20\nY,abc,20\n", "line 3: bad 'ra' 'abc'"),
    ("name,ra,dec\nX,10,95\n", "line 2: bad 'dec' '95' (Dec '95' is outside -90..+90"),
    ("name,ra,dec\nX,400,20\n", "line 2: bad 'ra' '400'"),
    ("name,ra,dec\n,10,20\n", "line 2: empty 'name'"),
    ("name,ra,dec,vmag\nX,10,20,bright\n", "line 2: bad 'vmag' 'bright'; expected a number"),
    ("name,ra,dec\nX,10\n", "line 2: 2 values but the header has 3 columns"),
    ("# only a comment\n", "no header row"),
])
def test_bad_rows_name_the_line_and_what_was_expected(text, message):
    with pytest.raises(StarCsvError) as info:
        read_star_csv_text(text, source="mine.csv")
    assert isinstance(info.value, ValueError)
    assert str(info.value).startswith("mine.csv, line ")
    assert message in str(info.value)


def test_line_numbers_count_comment_and_blank_lines():
    text = "# header comment\n\nname,ra,dec\n# skip\nX,10,20\nY,10,-91\n"
    with pytest.raises(StarCsvError) as info:
        read_star_csv_text(text)
    assert info.value.line_number == 6
