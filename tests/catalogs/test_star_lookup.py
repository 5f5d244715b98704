"""Finding stars by name, HIP number or designation, and the suggestions when none fits."""

from __future__ import annotations

import pytest

from catalogs import UnknownStar, bright_stars

VEGA_HIP = 91262


@pytest.mark.parametrize("query", [
    "Vega", "vega", "  VEGA ", "HIP 91262", "hip91262", "HIP  91262", "91262",
    "alf Lyr", "Alpha Lyrae", "α Lyr", "ALPHA LYR", "alpha-lyr", "alf Lyra", "3 Lyr", "3 Lyrae",
])
def test_lookup_finds_vega_by_every_spelling(query):
    assert bright_stars().lookup(query).hip == VEGA_HIP


@pytest.mark.parametrize(("query", "hip"), [
    ("Rigil Kentaurus", 71683), ("rigil  kentaurus", 71683), ("Rigel Kent", 71683),
    ("Betelgeuse", 27989), ("bet Ori", 24436), ("Theta Scorpii", 86228),
    ("eta UMa", 67301), ("Alkaid", 67301), ("Benetnash", 67301),
    ("xi Pup", 38170), ("ksi Pup", 38170), ("Zeta Puppis", 39429),
])
def test_lookup_accepts_names_aliases_and_designations(query, hip):
    assert bright_stars().lookup(query).hip == hip


def test_shared_designation_returns_the_brightest_component():
    # Both alf Cen A (HIP 71683, V=-0.01) and B (HIP 71681, V=1.35) carry 'alf Cen'.
    assert bright_stars().lookup("alf Cen").hip == 71683


def test_designation_without_component_number_finds_a_numbered_component():
    star = bright_stars().lookup("alf Cap")
    assert star.bayer in ("alf1 Cap", "alf2 Cap")


def test_unknown_name_raises_keyerror_with_did_you_mean():
    with pytest.raises(UnknownStar) as info:
        bright_stars().lookup("Vegaa")
    assert isinstance(info.value, KeyError)
    assert info.value.suggestions[0] == "Vega"
    assert "did you mean: Vega" in str(info.value)


def test_misspelt_name_suggests_the_right_star_first():
    with pytest.raises(UnknownStar) as info:
        bright_stars().lookup("Betelgeuze")
    assert info.value.suggestions[0] == "Betelgeuse"


def test_hip_number_outside_the_bundled_catalog_is_unknown():
    with pytest.raises(UnknownStar, match="HIP 1"):
        bright_stars().lookup("HIP 1")


def test_nonsense_gets_no_suggestions_but_says_what_is_accepted():
    with pytest.raises(UnknownStar) as info:
        bright_stars().lookup("qqqqqqqqqq")
    assert info.value.suggestions == []
    assert "HIP 91262" in str(info.value)


def test_contains_answers_without_raising():
    cat = bright_stars()
    assert "Vega" in cat and "Vegaa" not in cat
