"""UTC times as two-part Julian dates, and their TAI, TT and UT1 counterparts.

`UtcTimes` holds UTC in the ERFA quasi-JD convention (jd1 + jd2, each day
86400 "seconds" long, which makes it a continuous count like POSIX time).
Mount time is integer microseconds since 1970-01-01 UTC (POSIX, leap seconds
not counted), convertible both ways without rounding beyond 1 µs.
"""

from __future__ import annotations

import datetime as _dt
import warnings
from collections.abc import Iterable
from dataclasses import dataclass

import erfa
import numpy as np

from .constants import DAY_S, UNIX_EPOCH_JD
from .exceptions import TimeParseError

_US_PER_DAY = 86_400_000_000


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
        return cls(UNIX_EPOCH_JD + days.astype(float), rem / _US_PER_DAY)

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
        """Return mount time (int64 µs since 1970-01-01 UTC, POSIX)."""
        days = np.rint(self.jd1 - UNIX_EPOCH_JD).astype(np.int64)
        return days * _US_PER_DAY + np.rint(self.jd2 * _US_PER_DAY).astype(np.int64)

    def seconds_since(self, ref_jd1: float, ref_jd2: float = 0.0) -> np.ndarray:
        """Return UTC seconds elapsed since a reference two-part JD (float64)."""
        return ((self.jd1 - ref_jd1) + (self.jd2 - ref_jd2)) * DAY_S

    def shifted(self, seconds: np.ndarray | float) -> UtcTimes:
        """Return these times moved by `seconds` (POSIX seconds, no leap seconds)."""
        return UtcTimes.from_jd(self.jd1, self.jd2 + np.asarray(seconds) / DAY_S)

    def tai(self) -> tuple[np.ndarray, np.ndarray]:
        """Return TAI as two-part Julian dates (leap seconds from ERFA's table)."""
        return erfa.utctai(self.jd1, self.jd2)

    def tt(self) -> tuple[np.ndarray, np.ndarray]:
        """Return TT as two-part Julian dates."""
        return erfa.taitt(*self.tai())

    def ut1(self, dut1_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return UT1 two-part Julian dates given UT1-UTC in seconds."""
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


def _parse_one_iso(text: str) -> tuple[float, float]:
    raw = text.strip()
    cleaned = raw.replace(" ", "T", 1) if "T" not in raw and " " in raw else raw
    if cleaned.endswith(("Z", "z")):
        cleaned = cleaned[:-1] + "+00:00"
    try:
        stamp = _dt.datetime.fromisoformat(cleaned)
    except ValueError:
        raise TimeParseError(
            f"cannot read UTC time {text!r}: expected ISO 8601 like 2024-03-01T22:15:00Z "
            "or 2024-03-01 22:15:00.5"
        ) from None
    if stamp.tzinfo is not None:
        stamp = stamp.astimezone(_dt.UTC).replace(tzinfo=None)
    seconds = stamp.second + stamp.microsecond / 1e6
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", erfa.ErfaWarning)  # "dubious year" (future)
            return erfa.dtf2d("UTC", stamp.year, stamp.month, stamp.day, stamp.hour,
                              stamp.minute, seconds)
    except (erfa.ErfaError, ValueError) as exc:
        raise TimeParseError(f"cannot convert UTC time {text!r}: {exc}") from None
