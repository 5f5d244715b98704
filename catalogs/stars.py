"""Star records and a catalog that finds them by name, HIP number or designation."""

from __future__ import annotations

import csv
import difflib
import functools
import io
import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from importlib import resources

from catalogs.designations import designation_key, plain_key
from catalogs.exceptions import UnknownStar

HIPPARCOS_EPOCH_JYEAR = 1991.25  # ESA 1997, SP-1200 vol. 1 sect. 1.2; also used by van Leeuwen 2007
BRIGHT_STARS_RESOURCE = "bright_stars.csv"
MAX_SUGGESTIONS = 3

_HIP_QUERY = re.compile(r"^\s*(?:hip\s*)?(\d{1,6})\s*$", re.IGNORECASE)


@dataclass(frozen=True)
class Star:
    """One star: ICRS astrometry at ``epoch_jyear`` plus its names.

    Angles in degrees, proper motion in mas/yr (``pm_ra_cosdec`` is mu_alpha * cos(delta)),
    parallax in mas, radial velocity in km/s (positive receding; 0 when ``rv_known`` is False).
    """

    name: str
    hip: int | None
    bayer: str
    ra_deg: float
    dec_deg: float
    pm_ra_cosdec_mas_yr: float = 0.0
    pm_dec_mas_yr: float = 0.0
    parallax_mas: float = 0.0
    rv_km_s: float = 0.0
    vmag: float | None = None
    epoch_jyear: float = HIPPARCOS_EPOCH_JYEAR
    flamsteed: str = ""
    constellation: str = ""
    rv_known: bool = False
    aliases: tuple[str, ...] = field(default=())

    @property
    def label(self) -> str:
        """Return the best human label: name, else Bayer, Flamsteed or HIP designation."""
        return self.name or self.bayer or self.flamsteed or (f"HIP {self.hip}" if self.hip else "?")


class StarCatalog:
    """Stars indexed for lookup by name, alias, HIP number or Bayer/Flamsteed designation.

    Look-ups ignore case, spaces and punctuation.  When a designation is shared
    (e.g. 'alf Cen' for both components) the brightest star wins.
    """

    def __init__(self, stars: Iterable[Star]):
        self._stars: list[Star] = list(stars)
        self._by_key: dict[str, Star] = {}
        self._by_hip: dict[int, Star] = {}
        self._by_designation: dict[str, list[Star]] = {}
        for star in self._stars:
            self._index(star)

    def _index(self, star: Star) -> None:
        # Later stars (a user catalog merged after the bundled one) override earlier names.
        for name in (star.name, *star.aliases):
            if name:
                self._by_key[plain_key(name)] = star
        if star.hip is not None:
            self._by_hip[star.hip] = star
        for desig in (star.bayer, star.flamsteed):
            key = designation_key(desig) if desig else None
            if key:
                self._by_designation.setdefault(key, []).append(star)
                base = re.sub(r"\d(?=[a-z]+$)", "", key)  # 'alf1cap' also answers 'alf cap'
                if base != key:
                    self._by_designation.setdefault(base, []).append(star)

    def __len__(self) -> int:
        return len(self._stars)

    def __iter__(self) -> Iterator[Star]:
        return iter(self._stars)

    def __contains__(self, query: object) -> bool:
        return isinstance(query, str) and self._find(query) is not None

    def merged(self, other: StarCatalog | Iterable[Star]) -> StarCatalog:
        """Return a new catalog holding these stars and *other*'s (whose names win on clashes)."""
        return StarCatalog([*self._stars, *other])

    def by_hip(self, hip: int) -> Star:
        """Return the star with Hipparcos number *hip*; raises UnknownStar."""
        try:
            return self._by_hip[hip]
        except KeyError:
            raise UnknownStar(f"HIP {hip}", []) from None

    def lookup(self, query: str) -> Star:
        """Return the star named by *query*.

        Accepts a name or alias ("Vega"), a HIP number ("HIP 91262", "hip91262", "91262")
        or a Bayer/Flamsteed designation ("alf Lyr", "Alpha Lyrae", "α Lyr", "3 Lyr").
        Raises UnknownStar (a KeyError) listing close matches.
        """
        star = self._find(query)
        if star is None:
            raise UnknownStar(query, self.suggest(query))
        return star

    def _find(self, query: str) -> Star | None:
        m = _HIP_QUERY.match(query)
        if m:
            return self._by_hip.get(int(m.group(1)))
        star = self._by_key.get(plain_key(query))
        if star is not None:
            return star
        key = designation_key(query)
        if key and key in self._by_designation:
            return min(self._by_designation[key], key=_brightness)
        return None

    def suggest(self, query: str, n: int = MAX_SUGGESTIONS) -> list[str]:
        """Return up to *n* labels of stars whose names or designations resemble *query*."""
        labels: dict[str, str] = {}
        for star in self._stars:
            for text in (star.name, *star.aliases, star.bayer, star.flamsteed):
                if text:
                    labels.setdefault(plain_key(text), text)
        keys = difflib.get_close_matches(plain_key(query), list(labels), n=n, cutoff=0.6)
        return [labels[k] for k in keys]


def _brightness(star: Star) -> float:
    return star.vmag if star.vmag is not None else 99.0


def _flag(text: str) -> bool:
    return text.strip().lower() in ("1", "true", "yes")


def read_bundled_csv(text: str) -> list[Star]:
    """Parse the bundled bright-star CSV (comment lines start with '#')."""
    rows = csv.DictReader(io.StringIO("".join(
        line for line in text.splitlines(keepends=True) if not line.startswith("#")
    )))
    return [
        Star(
            name=r["name"],
            hip=int(r["hip"]),
            bayer=r["bayer"],
            flamsteed=r["flamsteed"],
            constellation=r["constellation"],
            ra_deg=float(r["ra_deg"]),
            dec_deg=float(r["dec_deg"]),
            pm_ra_cosdec_mas_yr=float(r["pm_ra_cosdec_mas_yr"]),
            pm_dec_mas_yr=float(r["pm_dec_mas_yr"]),
            parallax_mas=float(r["parallax_mas"]),
            rv_km_s=float(r["rv_km_s"]),
            rv_known=_flag(r["rv_known"]),
            vmag=float(r["vmag"]),
            epoch_jyear=HIPPARCOS_EPOCH_JYEAR,
            aliases=tuple(a for a in r["aliases"].split(";") if a),
        )
        for r in rows
    ]


@functools.cache
def bright_stars() -> StarCatalog:
    """Return the bundled catalog of Hipparcos stars to V = 4.0 (loaded once, then shared)."""
    text = resources.files("catalogs").joinpath("data", BRIGHT_STARS_RESOURCE).read_text("utf-8")
    return StarCatalog(read_bundled_csv(text))
