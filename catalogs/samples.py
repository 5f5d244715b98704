"""Bundled sample element sets (real CelesTrak data; see each set's description)."""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources
from pathlib import Path

from catalogs.exceptions import UnknownSampleSet


@dataclass(frozen=True)
class SampleSet:
    """A bundled element-set file and what it holds."""

    name: str
    filename: str
    description: str


SAMPLE_SETS = {
    s.name: s
    for s in (
        SampleSet("stations", "stations.tle",
                  "CelesTrak 'Space Stations' group, 27 objects incl. ISS (ZARYA) and CSS (TIANHE); "
                  "3-line TLE, epochs 2024-05-16/17 (ISS: 2024-05-17 23:54 UTC)"),
        SampleSet("visual", "visual.tle",
                  "8 bright satellites from CelesTrak's 'Visual' group incl. HST; 3-line TLE, "
                  "epochs 2021-07-23/24"),
        SampleSet("stations-omm", "stations.json",
                  "the 'stations' set as CelesTrak-style OMM JSON (made by "
                  "tools/build_sample_omm.py)"),
    )
}


def sample_tle_sets() -> list[str]:
    """Return the names of the bundled element sets."""
    return list(SAMPLE_SETS)


def sample_tle_path(name: str) -> Path:
    """Return the file path of bundled element set *name*; raises UnknownSampleSet."""
    try:
        sample = SAMPLE_SETS[name.strip().lower()]
    except KeyError:
        raise UnknownSampleSet(name, sample_tle_sets()) from None
    return Path(str(resources.files("catalogs").joinpath("data", sample.filename)))
