"""IERS Earth orientation (UT1-UTC, polar motion) read offline from astropy-iers-data.

The table is astropy's own IERS table (finals2000A.all merged with the IERS-B
EOP C04 series, both shipped in astropy-iers-data), loaded once with
auto-download off. Values are interpolated here, directly on the columns, in
the way astropy does it (linear in UTC MJD, UT1-UTC leap-second steps
removed), so that results agree with astropy's Time to ~1e-15 s while costing
nanoseconds per point instead of astropy's fixed ~2 s per call.
"""

from __future__ import annotations

import contextlib
import functools
import math
import os
import warnings
import weakref
from dataclasses import dataclass
from pathlib import Path

import erfa
import numpy as np

from .constants import ARCSEC_PER_RAD
from .exceptions import EarthOrientationWarning

_MJD_ZERO_JD = 2400000.5


@dataclass(frozen=True, eq=False)  # identity equality: usable as a cache key
class EarthOrientation:
    """Tabulated Earth orientation: daily UT1-UTC (s) and polar motion (arcsec).

    measured_until_mjd: last day of measured (non-predicted) values.
    """

    mjd: np.ndarray
    ut1_utc_s: np.ndarray
    xp_arcsec: np.ndarray
    yp_arcsec: np.ndarray
    measured_until_mjd: float
    source: str = "astropy-iers-data"

    @classmethod
    def from_astropy_iers_data(cls) -> EarthOrientation:
        """Return the shared table from astropy-iers-data (loaded once, never downloaded)."""
        return _default_table()

    def interpolate(
        self, jd1: np.ndarray, jd2: np.ndarray, *, warn: bool = True
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return (ut1_utc_s, xp_rad, yp_rad) at UTC two-part Julian dates.

        Warns EarthOrientationWarning when predictions are used, or when a time
        lies outside the table (the edge value is then held).
        """
        jd1 = np.asarray(jd1, float)
        jd2 = np.asarray(jd2, float)
        mjd = (jd1 - _MJD_ZERO_JD) + jd2
        mjd_table = self.mjd
        i1 = np.clip(np.searchsorted(mjd_table, mjd, side="right"), 1, len(mjd_table) - 1)
        i0 = i1 - 1
        m0 = mjd_table[i0]
        frac = (mjd - m0) / (mjd_table[i1] - m0)
        outside = (mjd < mjd_table[0]) | (mjd > mjd_table[-1])
        frac = np.where(outside, np.where(mjd < mjd_table[0], 0.0, 1.0), frac)
        u0 = self.ut1_utc_s[i0]
        du = self.ut1_utc_s[i1] - u0
        du -= np.round(du)  # a leap second shows as a 1 s step: interpolate across it
        dut1 = u0 + frac * du
        x0 = self.xp_arcsec[i0]
        y0 = self.yp_arcsec[i0]
        xp = (x0 + frac * (self.xp_arcsec[i1] - x0)) / ARCSEC_PER_RAD
        yp = (y0 + frac * (self.yp_arcsec[i1] - y0)) / ARCSEC_PER_RAD
        if warn and mjd.size:
            self._warn_if_not_measured(mjd, outside)
        return dut1, xp, yp

    def _warn_if_not_measured(self, mjd: np.ndarray, outside: np.ndarray) -> None:
        if outside.any():
            self._warn_once("outside",
                f"a time lies outside the IERS table of {self.source} "
                f"({_mjd_date(self.mjd[0])} .. {_mjd_date(self.mjd[-1])}): UT1-UTC and polar "
                "motion are held at the edge value, and leap seconds announced later are "
                "unknown. UT1-UTC drifts by up to ~1 s a year, and each second of it turns the "
                "sky by 15 arcsec: stars (hour angle, hence az/el) may be off by arcseconds to "
                "tens of arcseconds, LEO satellites by arcminutes. Update astropy-iers-data.")
        elif float(np.max(mjd)) > self.measured_until_mjd + 1.0:
            self._warn_once("predicted",
                f"a time lies after the last measured IERS value "
                f"({_mjd_date(self.measured_until_mjd)}, {self.source}): predicted UT1-UTC and "
                "polar motion are used (good to a few ms and mas for weeks, worse later: "
                "stars within a fraction of an arcsecond, a LEO satellite may be off by "
                "arcseconds). Update astropy-iers-data.")

    def _warn_once(self, kind: str, message: str) -> None:
        # Once per table and kind: a server asks for every trajectory chunk, and any
        # warnings.catch_warnings() elsewhere resets Python's own once-per-place registry.
        said = _WARNED.setdefault(self, set())
        if kind not in said:
            said.add(kind)
            warnings.warn(message, EarthOrientationWarning, stacklevel=4)


_WARNED: weakref.WeakKeyDictionary[EarthOrientation, set[str]] = weakref.WeakKeyDictionary()


def _mjd_date(mjd: float) -> str:
    y, m, d, _ = erfa.jd2cal(_MJD_ZERO_JD, float(mjd))
    return f"{int(y):04d}-{int(m):02d}-{int(d):02d}"


#: Where the table read from astropy-iers-data is kept as arrays, so that later processes
#: need not import astropy (~1 s and ~100 MB at its peak): $VIRTUALSTAR_CACHE_DIR, else
#: $XDG_CACHE_HOME/virtualstar, else ~/.cache/virtualstar. One file per astropy and
#: astropy-iers-data version: a new table is read again.
CACHE_ENV_VAR = "VIRTUALSTAR_CACHE_DIR"
_FIELDS = ("mjd", "ut1_utc_s", "xp_arcsec", "yp_arcsec")


def eop_cache_path() -> Path | None:
    """Return the cache file of the astropy-iers-data table, None when no version is known."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        key = f"astropy-{version('astropy')}-iers-{version('astropy-iers-data')}"
    except PackageNotFoundError:
        return None
    root = os.environ.get(CACHE_ENV_VAR) or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "virtualstar")
    return Path(root) / f"eop-{key}.npz"


@functools.cache
def _default_table() -> EarthOrientation:
    path = eop_cache_path()
    if path is not None:
        cached = _read_cache(path)
        if cached is None:
            # astropy reads the table in a child process: its import and its reading (about
            # 100 MB at their peak, and what it keeps) stay out of this one
            _fill_cache_in_a_child(path)
            cached = _read_cache(path)
        if cached is not None:
            return cached
    return _read_astropy_table()  # no cache to be had: read it here


def _fill_cache_in_a_child(path: Path) -> None:
    import subprocess
    import sys

    code = ("import sys\nfrom pathlib import Path\n"
            "from virtualstar.astro.earth_orientation import _read_astropy_table, _write_cache\n"
            "_write_cache(Path(sys.argv[1]), _read_astropy_table())\n")
    with contextlib.suppress(OSError, subprocess.SubprocessError):  # then we read it here
        subprocess.run([sys.executable, "-c", code, str(path)], stdin=subprocess.DEVNULL,
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=600,
                       check=False)


def _read_cache(path: Path) -> EarthOrientation | None:
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {name: np.array(z[name], dtype=float) for name in _FIELDS}
            measured = float(z["measured_until_mjd"])
    except (OSError, KeyError, ValueError, EOFError):
        return None  # none yet, or not one we wrote: read astropy's again
    n = len(arrays["mjd"])
    if n < 2 or any(a.shape != (n,) for a in arrays.values()):
        return None
    return EarthOrientation(**arrays, measured_until_mjd=measured)


def _write_cache(path: Path, table: EarthOrientation) -> None:
    """Keep the arrays for later processes; a cache that cannot be written is no error."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f"{path.stem}.{os.getpid()}.tmp.npz")
        np.savez(tmp, **{name: getattr(table, name) for name in _FIELDS},
                 measured_until_mjd=table.measured_until_mjd)
        os.replace(tmp, path)  # whole or absent, whoever else writes it at the same time
    except OSError:
        pass


def _read_astropy_table() -> EarthOrientation:
    from astropy.utils import iers

    iers.conf.auto_download = False
    table = iers.earth_orientation_table.get()
    mjd = np.asarray(table["MJD"].to_value("d"), float)
    flags = np.asarray(table["UT1Flag"]).astype(str)
    measured = mjd[flags != "P"]
    return EarthOrientation(
        mjd=mjd,
        ut1_utc_s=np.asarray(table["UT1_UTC"].to_value("s"), float),
        xp_arcsec=np.asarray(table["PM_x"].to_value("arcsec"), float),
        yp_arcsec=np.asarray(table["PM_y"].to_value("arcsec"), float),
        measured_until_mjd=float(measured[-1]) if measured.size else -math.inf,
    )
