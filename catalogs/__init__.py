"""Bundled bright-star catalog, sample TLE sets and loaders for user catalogs.

    from catalogs import bright_stars, load_tle_file, sample_tle_path
    vega = bright_stars().lookup("alf Lyr")          # Star, ICRS at epoch J1991.25
    iss = load_tle_file(sample_tle_path("stations"))[0]
"""

from catalogs.exceptions import (
    CatalogError,
    ElementFileError,
    OmmFormatError,
    StarCsvError,
    TleChecksumError,
    TleEpochWarning,
    TleFormatError,
    UnknownSampleSet,
    UnknownSatellite,
    UnknownStar,
)
from catalogs.omm import parse_omm_json
from catalogs.samples import sample_tle_path, sample_tle_sets
from catalogs.stars import HIPPARCOS_EPOCH_JYEAR, Star, StarCatalog, bright_stars
from catalogs.tle import (
    MAX_EPOCH_AGE_DAYS,
    TEMPLATE_LINE1,
    TEMPLATE_LINE2,
    TleElements,
    TleRecord,
    check_epoch,
    epoch_age_days,
    load_tle_file,
    parse_tle_text,
    read_element_text,
    select_satellite,
    tle_checksum,
)
from catalogs.user_catalog import (
    load_star_csv,
    parse_dec_deg,
    parse_ra_deg,
    read_star_csv,
    read_star_csv_text,
)

__all__ = [
    "HIPPARCOS_EPOCH_JYEAR",
    "MAX_EPOCH_AGE_DAYS",
    "TEMPLATE_LINE1",
    "TEMPLATE_LINE2",
    "CatalogError",
    "ElementFileError",
    "OmmFormatError",
    "Star",
    "StarCatalog",
    "StarCsvError",
    "TleChecksumError",
    "TleElements",
    "TleEpochWarning",
    "TleFormatError",
    "TleRecord",
    "UnknownSampleSet",
    "UnknownSatellite",
    "UnknownStar",
    "bright_stars",
    "check_epoch",
    "epoch_age_days",
    "load_star_csv",
    "load_tle_file",
    "read_element_text",
    "parse_dec_deg",
    "parse_omm_json",
    "parse_ra_deg",
    "parse_tle_text",
    "read_star_csv",
    "read_star_csv_text",
    "sample_tle_path",
    "sample_tle_sets",
    "select_satellite",
    "tle_checksum",
]
