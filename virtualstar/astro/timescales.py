"""UTC times as two-part Julian dates, and their TAI, TT and UT1 counterparts.

`UtcTimes` holds UTC in ERFA's quasi-JD convention: jd1 + jd2 where the
fraction of a day is the UTC seconds elapsed that day divided by the day's own
length — 86 401 s on a day that ends in a leap second, so 23:59:60.5 exists.
ERFA's UTC functions (utctai, utcut1, d2dtf, apco13, ...) take exactly that.

Mount time is integer microseconds since 1970-01-01 UTC counted the POSIX way:
86 400 s a day, leap seconds not counted (23:59:60.x reads as the next day's
00:00:00.x). Conversions between the two scale the day fraction by the day's
real length, so an instant on a leap-second day is the same instant in both;
`seconds_since` and `shifted` count POSIX seconds (the continuous UTC count that
SGP4, skyfield and the mount use).

Anything interpolated in time (a spline of a star's direction, the Earth's rotation
between two nodes) must use *elapsed* seconds instead: `si_seconds_since` and
`si_shifted` count SI seconds (TAI), so the last hour of a leap-second day lasts
3 601 s there, as the Earth's rotation sees it. POSIX seconds would squeeze 3 601 s
of rotation into 3 600 and be up to a whole second (15″ of the sky) off at 23:59:59.
"""

from __future__ import annotations

import datetime as _dt
import functools
import re
import warnings
from collections.abc import Iterable
from dataclasses import dataclass

import erfa
import numpy as np

from .constants import DAY_S, UNIX_EPOCH_JD
from .exceptions import TimeParseError

_US_PER_DAY = 86_400_000_000
_LEAP_SECOND = re.compile(r"^(.*T\d{2}:\d{2}:)60((?:[.,]\d+)?(?:[+-]\d{2}:?\d{2})?)$")


@dataclass(frozen=True)
class UtcTimes:
    """An array of UTC instants as two-part Julian dates (ERFA convention)."""

    jd1: np.ndarray
    jd2: np.ndarray

    @classmethod
    def from_jd(cls, jd1: np.ndarray | float, jd2: np.ndarray | float = 0.0) -> UtcTimes:
        """Build from UTC two-part Julian dates (arrays broadcast)."""
        a, b = np.broadcast_arrays(np.atleast_1d(np.asarray(jd1, float)),
                                   np.atleast_1d(np.asarray(jd2, float)))
        whole = np.floor(a) + 0.5
        frac = (a - whole) + b
        shift = np.floor(frac)
        return cls(whole + shift, frac - shift)

    @classmethod
    def from_unix_us(cls, t_us: np.ndarray | int) -> UtcTimes:
        """Build from mount time: integer microseconds since 1970-01-01 UTC (POSIX)."""
        t = np.atleast_1d(np.asarray(t_us, dtype=np.int64))
        days, rem = np.divmod(t, _US_PER_DAY)
        return cls.from_posix_days(days, rem / 1e6)

    @classmethod
    def from_posix_days(cls, days: np.ndarray, sec_of_day: np.ndarray) -> UtcTimes:
        """Build from whole POSIX days since 1970 and seconds into that day (may exceed 86 400)."""
        extra = np.floor(np.asarray(sec_of_day) / DAY_S).astype(np.int64)
        days = np.asarray(days, dtype=np.int64) + extra
        sec_of_day = np.asarray(sec_of_day) - extra * DAY_S
        jd1 = UNIX_EPOCH_JD + days.astype(float)
        return cls(jd1, sec_of_day / day_length_s(jd1))

    @classmethod
    def from_iso(cls, texts: Iterable[str]) -> UtcTimes:
        """Parse ISO 8601 UTC strings ("2024-03-01T22:15:00Z", "2024-03-01 22:15").

        Raises TimeParseError naming the bad string and the expected layout.
        """
        jd1, jd2 = [], []
        for text in texts:
            a, b = _parse_one_iso(text)
            jd1.append(a)
            jd2.append(b)
        return cls.from_jd(np.array(jd1), np.array(jd2))

    @classmethod
    def now(cls) -> UtcTimes:
        """Return the current UTC time from the system clock."""
        now = _dt.datetime.now(_dt.UTC)
        return cls.from_unix_us(int(now.timestamp() * 1_000_000))

    def __len__(self) -> int:
        return self.jd1.shape[0]

    def __getitem__(self, index) -> UtcTimes:
        return UtcTimes(np.ascontiguousarray(np.atleast_1d(self.jd1[index])),
                        np.ascontiguousarray(np.atleast_1d(self.jd2[index])))

    def to_unix_us(self) -> np.ndarray:
        """Return mount time (int64 µs since 1970-01-01 UTC, POSIX).

        An instant inside a leap second (23:59:60.x) gives the next day's 00:00:00.x.
        """
        days, sec = self.posix_days()
        return days * _US_PER_DAY + np.rint(sec * 1e6).astype(np.int64)

    def posix_days(self) -> tuple[np.ndarray, np.ndarray]:
        """Return (whole POSIX days since 1970, seconds into the day) of these instants."""
        day = UtcTimes.from_jd(self.jd1, self.jd2)  # jd1 at 0h, 0 <= jd2 < 1
        days = np.rint(day.jd1 - UNIX_EPOCH_JD).astype(np.int64)
        return days, day.jd2 * day_length_s(day.jd1)

    def posix_jd(self) -> tuple[np.ndarray, np.ndarray]:
        """Return UTC as a continuous count, (JD of the day, POSIX seconds/86 400): SGP4's time.

        The count holds at the day's end through a leap second (23:59:60.x reads as
        24:00:00.0): SGP4 counts UTC in 86 400-s days, so it cannot place an instant
        inside the leap second; holding keeps the count continuous and never running
        backwards (POSIX would read 00:00:00.x twice). See docs/astronomy.md.
        """
        days, sec = self.posix_days()
        return UNIX_EPOCH_JD + days.astype(float), np.minimum(sec, DAY_S) / DAY_S

    def in_leap_second(self) -> np.ndarray:
        """Return whether each instant lies inside a leap second (23:59:60.x), bool (N,)."""
        _, sec = self.posix_days()
        return sec >= DAY_S

    def seconds_since(self, ref_jd1: float, ref_jd2: float = 0.0) -> np.ndarray:
        """Return POSIX seconds elapsed since a reference UTC two-part JD (float64)."""
        days, sec = self.posix_days()
        ref_days, ref_sec = UtcTimes.from_jd(ref_jd1, ref_jd2).posix_days()
        return (days - ref_days[0]).astype(float) * DAY_S + (sec - ref_sec[0])

    def shifted(self, seconds: np.ndarray | float) -> UtcTimes:
        """Return these times moved by `seconds` (POSIX seconds, no leap seconds)."""
        days, sec = self.posix_days()
        return UtcTimes.from_posix_days(days, sec + np.asarray(seconds, dtype=float))

    def si_seconds_since(self, ref_jd1: float, ref_jd2: float = 0.0) -> np.ndarray:
        """Return SI seconds (TAI) elapsed since a reference UTC two-part JD (float64).

        Equal to `seconds_since` except across a leap second, which is counted here.
        """
        days, sec = self.posix_days()
        ref_days, ref_sec = UtcTimes.from_jd(ref_jd1, ref_jd2).posix_days()
        out = (days - ref_days[0]).astype(float) * DAY_S + (sec - ref_sec[0])
        first_jd = UNIX_EPOCH_JD + float(min(int(days.min()), int(ref_days[0])))
        last_jd = UNIX_EPOCH_JD + float(max(int(days.max()), int(ref_days[0])))
        if _tai_minus_utc(first_jd) == _tai_minus_utc(last_jd):
            return out  # no leap second between them: the POSIX count is the SI count
        day_jd, index = np.unique(UNIX_EPOCH_JD + days.astype(float), return_inverse=True)
        dat = np.array([_tai_minus_utc(float(d)) for d in day_jd])[index].reshape(days.shape)
        return out + (dat - _tai_minus_utc(UNIX_EPOCH_JD + float(ref_days[0])))

    def si_shifted(self, seconds: np.ndarray | float) -> UtcTimes:
        """Return these times moved by `seconds` SI seconds (TAI): a leap second counts."""
        tai1, tai2 = self.tai()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", erfa.ErfaWarning)  # "dubious year", as in tai()
            utc1, utc2 = erfa.taiutc(tai1, tai2 + np.asarray(seconds, dtype=float) / DAY_S)
        return UtcTimes.from_jd(utc1, utc2)

    def tai(self) -> tuple[np.ndarray, np.ndarray]:
        """Return TAI as two-part Julian dates (leap seconds from ERFA's table).

        ERFA's "dubious year" for dates after its table could know of a new leap second
        is not passed on: EarthOrientation says what a date beyond the IERS table costs.
        """
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", erfa.ErfaWarning)
            return erfa.utctai(self.jd1, self.jd2)

    def tt(self) -> tuple[np.ndarray, np.ndarray]:
        """Return TT as two-part Julian dates."""
        return erfa.taitt(*self.tai())

    def ut1(self, dut1_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return UT1 two-part Julian dates given UT1-UTC in seconds (no "dubious year")."""
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", erfa.ErfaWarning)
            return erfa.utcut1(self.jd1, self.jd2, dut1_s)

    def iso(self, decimals: int = 3) -> list[str]:
        """Return ISO 8601 UTC strings ending in Z."""
        out = []
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", erfa.ErfaWarning)  # "dubious year": leap seconds
            fields = erfa.d2dtf("UTC", decimals, self.jd1, self.jd2)  # unknown, still fine
        for y, mo, d, hmsf in zip(*fields, strict=True):
            h, mi, s, f = (int(v) for v in hmsf)
            frac = f".{f:0{decimals}d}" if decimals else ""
            out.append(f"{y:04d}-{mo:02d}-{d:02d}T{h:02d}:{mi:02d}:{s:02d}{frac}Z")
        return out


def iso_utc(t_us: int, digits: int = 0) -> str:
    """Return one time in µs since 1970 (UTC; mount time) as ISO-8601 UTC text with
    `digits` decimals of the second."""
    return UtcTimes.from_unix_us(int(t_us)).iso(digits)[0]


def day_length_s(jd1: np.ndarray) -> np.ndarray | float:
    """Return the length in seconds of the UTC days whose JD (at 0h, jd1 ≡ .5) is given.

    86 400 except on a day that ends in a leap second (ERFA's table). Fast path: when no
    leap second falls between the first and the last day, one scalar 86 400 is returned.
    """
    jd1 = np.asarray(jd1, dtype=float)
    if jd1.size == 0:
        return DAY_S
    first, last = float(np.min(jd1)), float(np.max(jd1))
    if _tai_minus_utc(first) == _tai_minus_utc(last + 1.0):
        return DAY_S
    days, index = np.unique(jd1, return_inverse=True)
    lengths = np.array([DAY_S + _tai_minus_utc(d + 1.0) - _tai_minus_utc(d) for d in days])
    return lengths[index].reshape(jd1.shape)


@functools.lru_cache(maxsize=4096)
def _tai_minus_utc(jd_0h: float) -> float:
    """Return TAI − UTC (s) at 0h UTC of the day starting at `jd_0h` (ERFA's leap-second table)."""
    with warnings.catch_warnings():
        # "dubious year": after ERFA's table could know of a leap second; the last value holds
        warnings.simplefilter("ignore", erfa.ErfaWarning)
        y, m, d, _ = erfa.jd2cal(jd_0h, 0.0)
        return float(erfa.dat(y, m, d, 0.0))


def _parse_one_iso(text: str) -> tuple[float, float]:
    raw = text.strip()
    cleaned = raw.replace(" ", "T", 1) if "T" not in raw and " " in raw else raw
    if cleaned.endswith(("Z", "z")):
        cleaned = cleaned[:-1] + "+00:00"
    # 23:59:60.x, a leap second: datetime cannot hold it, ERFA can (and refuses it on a day
    # that has none)
    leap = _LEAP_SECOND.match(cleaned)
    if leap:
        cleaned = leap.group(1) + "59" + leap.group(2)
    try:
        stamp = _dt.datetime.fromisoformat(cleaned)
    except ValueError:
        raise TimeParseError(
            f"cannot read UTC time {text!r}: expected ISO 8601 like 2024-03-01T22:15:00Z "
            "or 2024-03-01 22:15:00.5"
        ) from None
    if stamp.tzinfo is not None:
        stamp = stamp.astimezone(_dt.UTC).replace(tzinfo=None)
    seconds = stamp.second + (1 if leap else 0) + stamp.microsecond / 1e6
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", erfa.ErfaWarning)
            jd = erfa.dtf2d("UTC", stamp.year, stamp.month, stamp.day, stamp.hour,
                            stamp.minute, seconds)
        # "dubious year" (a future date) is fine; "after end of day" is a second 60 on a
        # day without a leap second
        if any("end of day" in str(w.message) for w in caught):
            raise ValueError("time is after end of day")
        return jd
    except (erfa.ErfaError, ValueError) as exc:
        if leap:
            raise TimeParseError(f"cannot read UTC time {text!r}: there is no leap second "
                                 "at the end of that day (second 60 exists only on days that "
                                 "end in one, e.g. 2016-12-31)") from None
        raise TimeParseError(f"cannot convert UTC time {text!r}: {exc}") from None
