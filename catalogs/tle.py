"""Two-line element sets: read, validate column by column, and check their age.

The column layout follows the NORAD/Space-Track "Two-Line Element Set Format"
(columns are 1-based below, as in that document).  Files may hold 2-line sets or
3-line sets (a name line, optionally prefixed "0 ", before each pair).
"""

from __future__ import annotations

import math
import os
import stat
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from pathlib import Path

from sgp4.api import Satrec

from catalogs.exceptions import (
    ElementFileError,
    TleChecksumError,
    TleEpochWarning,
    TleFormatError,
    UnknownSatellite,
)

MAX_EPOCH_AGE_DAYS = 14.0
TLE_LINE_LENGTH = 69

# What each column must hold: N digit, n digit or space, C classification letter,
# A letter/digit/space, + sign or space, - sign/space/digit, . decimal point, 'space' blank.
TEMPLATE_LINE1 = "1 NNNNNC NNNNNAAA NNNNN.NNNNNNNN +.NNNNNNNN +NNNNN-N +NNNNN-N N NNNNN"
TEMPLATE_LINE2 = "2 NNNNN NNN.NNNN NNN.NNNN NNNNNNN NNN.NNNN NNN.NNNN NN.NNNNNNNNNNNNNN"

# (first column, last column, allowed characters, what the field is) -- 1-based, inclusive.
_DIGITS = "0123456789"
_DIGITS_BLANK = _DIGITS + " "
_ALPHA5 = "ABCDEFGHJKLMNPQRSTUVWXYZ" + _DIGITS  # Alpha-5 satellite numbers skip I and O
_LINE1_FIELDS = (
    (1, 1, "1", "line number 1"),
    (2, 2, " ", "a blank"),
    (3, 3, _ALPHA5, "satellite number"),
    (4, 7, _DIGITS, "satellite number"),
    (8, 8, "UCS ", "classification (U, C or S)"),
    (9, 9, " ", "a blank"),
    (10, 17, _DIGITS_BLANK + "ABCDEFGHIJKLMNOPQRSTUVWXYZ", "international designator"),
    (18, 18, " ", "a blank"),
    (19, 20, _DIGITS, "epoch year"),
    (21, 23, _DIGITS, "epoch day of year"),
    (24, 24, ".", "the epoch's decimal point"),
    (25, 32, _DIGITS, "epoch fraction of day"),
    (33, 33, " ", "a blank"),
    (34, 34, "+- ", "sign of ndot/2"),
    (35, 35, ".", "ndot/2's decimal point"),
    (36, 43, _DIGITS, "ndot/2 digits"),
    (44, 44, " ", "a blank"),
    (45, 45, "+- ", "sign of nddot/6"),
    (46, 50, _DIGITS, "nddot/6 mantissa"),
    (51, 51, "+-", "nddot/6 exponent sign"),
    (52, 52, _DIGITS, "nddot/6 exponent"),
    (53, 53, " ", "a blank"),
    (54, 54, "+- ", "sign of BSTAR"),
    (55, 59, _DIGITS, "BSTAR mantissa"),
    (60, 60, "+-", "BSTAR exponent sign"),
    (61, 61, _DIGITS, "BSTAR exponent"),
    (62, 62, " ", "a blank"),
    (63, 63, _DIGITS, "ephemeris type"),
    (64, 64, " ", "a blank"),
    (65, 68, _DIGITS_BLANK, "element set number"),
    (69, 69, _DIGITS, "checksum"),
)
_LINE2_FIELDS = (
    (1, 1, "2", "line number 2"),
    (2, 2, " ", "a blank"),
    (3, 3, _ALPHA5, "satellite number"),
    (4, 7, _DIGITS, "satellite number"),
    (8, 8, " ", "a blank"),
    (9, 11, _DIGITS_BLANK, "inclination degrees"),
    (12, 12, ".", "inclination's decimal point"),
    (13, 16, _DIGITS, "inclination decimals"),
    (17, 17, " ", "a blank"),
    (18, 20, _DIGITS_BLANK, "right ascension of the node degrees"),
    (21, 21, ".", "node's decimal point"),
    (22, 25, _DIGITS, "node decimals"),
    (26, 26, " ", "a blank"),
    (27, 33, _DIGITS, "eccentricity (decimal point assumed)"),
    (34, 34, " ", "a blank"),
    (35, 37, _DIGITS_BLANK, "argument of perigee degrees"),
    (38, 38, ".", "perigee's decimal point"),
    (39, 42, _DIGITS, "argument of perigee decimals"),
    (43, 43, " ", "a blank"),
    (44, 46, _DIGITS_BLANK, "mean anomaly degrees"),
    (47, 47, ".", "mean anomaly's decimal point"),
    (48, 51, _DIGITS, "mean anomaly decimals"),
    (52, 52, " ", "a blank"),
    (53, 54, _DIGITS_BLANK, "mean motion revolutions/day"),
    (55, 55, ".", "mean motion's decimal point"),
    (56, 63, _DIGITS, "mean motion decimals"),
    (64, 68, _DIGITS_BLANK, "revolution number"),
    (69, 69, _DIGITS, "checksum"),
)


@dataclass(frozen=True)
class TleElements:
    """The fields of one element set as printed (degrees, revolutions/day, UTC)."""

    satnum: int
    classification: str
    intldesg: str
    epoch_utc: datetime
    ndot_rev_day2: float  # first derivative of mean motion / 2, as printed
    nddot_rev_day3: float  # second derivative / 6, as printed
    bstar_per_earth_radius: float
    ephemeris_type: int
    element_number: int
    inclination_deg: float
    raan_deg: float
    eccentricity: float
    arg_perigee_deg: float
    mean_anomaly_deg: float
    mean_motion_rev_day: float
    rev_number: int


@dataclass(frozen=True)
class TleRecord:
    """One satellite's elements: name, the two TLE lines, and where they came from.

    Records read from OMM keep the OMM fields in ``omm`` and build their Satrec from
    them (full precision); their ``line1``/``line2`` are the same elements rounded to
    TLE precision by sgp4's exporter.
    """

    name: str
    line1: str
    line2: str
    source: str = ""
    omm: Mapping[str, str] | None = field(default=None, compare=False, repr=False)

    @property
    def satnum(self) -> int:
        """Return the NORAD catalog number."""
        return self.elements.satnum

    @property
    def epoch_utc(self) -> datetime:
        """Return the epoch of the elements as an aware UTC datetime."""
        return self.elements.epoch_utc

    @property
    def elements(self) -> TleElements:
        """Return the fields of line 1 and 2, parsed column by column."""
        return parse_elements(self.line1, self.line2)

    def satrec(self) -> Satrec:
        """Return an initialised sgp4 Satrec (WGS72, as the elements were fitted)."""
        if self.omm is not None:
            from sgp4 import omm

            sat = Satrec()
            omm.initialize(sat, self.omm)
            return sat
        return Satrec.twoline2rv(self.line1, self.line2)


def tle_checksum(line: str) -> int:
    """Return the modulo-10 checksum of columns 1-68: digits count their value, '-' counts 1."""
    return sum(int(c) if c.isdigit() else (c == "-") for c in line[:68]) % 10


def _satnum(text: str) -> int:
    # Alpha-5: a leading letter stands for 10..33 (I and O skipped), e.g. A0000 = 100000.
    head = text[0]
    if head.isdigit():
        return int(text)
    return (10 + "ABCDEFGHJKLMNPQRSTUVWXYZ".index(head)) * 10000 + int(text[1:])


def _implied(text: str) -> float:
    """Read ' 12345-4' style fields: sign, mantissa with assumed leading '0.', exponent."""
    text = text.replace(" ", "") or "0"
    sign = -1.0 if text[0] == "-" else 1.0
    text = text.lstrip("+-")
    return sign * float("0." + text[:-2]) * 10.0 ** int(text[-2:])


def parse_elements(line1: str, line2: str) -> TleElements:
    """Parse already-validated TLE lines into their printed fields."""
    year = int(line1[18:20])
    year += 1900 if year >= 57 else 2000  # TLE convention: 57-99 -> 1957-1999
    day = float(line1[20:32])
    epoch = datetime(year, 1, 1, tzinfo=UTC) + timedelta(days=day - 1.0)
    return TleElements(
        satnum=_satnum(line1[2:7]),
        classification=line1[7],
        intldesg=line1[9:17].strip(),
        epoch_utc=epoch,
        ndot_rev_day2=float(line1[33:43].replace(" ", "")),
        nddot_rev_day3=_implied(line1[44:52]),
        bstar_per_earth_radius=_implied(line1[53:61]),
        ephemeris_type=int(line1[62]),
        element_number=int(line1[64:68] or 0),
        inclination_deg=float(line2[8:16]),
        raan_deg=float(line2[17:25]),
        eccentricity=float("0." + line2[26:33]),
        arg_perigee_deg=float(line2[34:42]),
        mean_anomaly_deg=float(line2[43:51]),
        mean_motion_rev_day=float(line2[52:63]),
        rev_number=int(line2[63:68].strip() or 0),
    )


def _check_line(line: str, number: int, source: str, line_number: int) -> None:
    template, fields = (TEMPLATE_LINE1, _LINE1_FIELDS) if number == 1 else (TEMPLATE_LINE2, _LINE2_FIELDS)

    def fail(problem: str, column: int | None, cls: type[TleFormatError] = TleFormatError):
        raise cls(source, line_number, line, problem, template, column)

    if len(line) != TLE_LINE_LENGTH:
        fail(f"TLE line {number} has {len(line)} columns, expected {TLE_LINE_LENGTH}",
             min(len(line), TLE_LINE_LENGTH) + 1 if len(line) < TLE_LINE_LENGTH else TLE_LINE_LENGTH + 1)
    for first, last, allowed, what in fields:
        for col in range(first, last + 1):
            if line[col - 1] not in allowed:
                fail(f"column {col} of TLE line {number} is {line[col - 1]!r}, expected {what}", col)
    expected = tle_checksum(line)
    if int(line[68]) != expected:
        fail(f"checksum of TLE line {number} is {expected} but column 69 says {line[68]}",
             69, TleChecksumError)


def _validate_pair(line1: str, line2: str, source: str, line_number: int) -> None:
    _check_line(line1, 1, source, line_number)
    _check_line(line2, 2, source, line_number + 1)
    if line1[2:7] != line2[2:7]:
        raise TleFormatError(
            source, line_number + 1, line2,
            f"satellite number {line2[2:7].strip()!r} of line 2 differs from line 1's "
            f"{line1[2:7].strip()!r}", TEMPLATE_LINE2, 3,
        )


def parse_tle_text(text: str, source: str = "<string>") -> list[TleRecord]:
    """Parse 2-line or 3-line (named) TLE text; raises TleFormatError naming the bad line.

    Blank lines are skipped; a name line may carry the "0 " prefix of 3LE files.
    A 2-line set without a name gets its catalog number as name.
    """
    records: list[TleRecord] = []
    lines = [(i + 1, raw.rstrip("\r\n")) for i, raw in enumerate(text.splitlines())]
    lines = [(n, raw.rstrip()) for n, raw in lines if raw.strip()]
    i = 0
    while i < len(lines):
        n, line = lines[i]
        name = ""
        if not line.startswith(("1 ", "2 ")):
            name = line[2:].strip() if line.startswith("0 ") else line.strip()
            i += 1
            if i >= len(lines):
                raise TleFormatError(source, n, line, f"name {name!r} is not followed by TLE lines",
                                     TEMPLATE_LINE1)
            n, line = lines[i]
        if not line.startswith("1"):
            after = f" after the name {name!r}" if name else ""
            raise TleFormatError(source, n, line, f"expected TLE line 1{after}", TEMPLATE_LINE1, 1)
        if i + 1 >= len(lines):
            raise TleFormatError(source, n, line, "TLE line 1 is not followed by line 2",
                                 TEMPLATE_LINE2)
        n2, line2 = lines[i + 1]
        if not line2.startswith("2"):
            raise TleFormatError(source, n2, line2, "expected TLE line 2 here", TEMPLATE_LINE2, 1)
        _validate_pair(line, line2, source, n)
        records.append(TleRecord(name or line[2:7].strip(), line, line2, source))
        i += 2
    return records


#: The largest element file read (CelesTrak's whole active catalogue is ~3 MB as TLE).
MAX_ELEMENT_FILE_BYTES = 64 * 1024 * 1024


def read_element_text(path: str | Path) -> str:
    """Return the text of a TLE/OMM file: a regular file of at most MAX_ELEMENT_FILE_BYTES,
    UTF-8. Raises ElementFileError saying what the path is instead (no such file, a device
    such as /dev/zero, a FIFO, a directory, too big, not text); never blocks on a FIFO."""
    path = Path(path)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        raise ElementFileError(f"{path}: no such file") from None
    except OSError as exc:
        raise ElementFileError(f"{path}: cannot open: {exc.strerror or exc}") from None
    except ValueError:  # a NUL in the name: no file can have it
        raise ElementFileError(f"{str(path)!r}: a path cannot hold a NUL character") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise ElementFileError(f"{path} is {_file_kind(st.st_mode)}, not a regular file; "
                                   "expected a TLE (2/3-line) or OMM JSON text file")
        if st.st_size > MAX_ELEMENT_FILE_BYTES:
            raise ElementFileError(f"{path} holds {st.st_size} bytes, more than the "
                                   f"{MAX_ELEMENT_FILE_BYTES} an element file may; "
                                   "expected a TLE (2/3-line) or OMM JSON text file")
        with os.fdopen(os.dup(fd), "rb") as f:
            data = f.read(MAX_ELEMENT_FILE_BYTES + 1)
    finally:
        os.close(fd)
    if len(data) > MAX_ELEMENT_FILE_BYTES:
        raise ElementFileError(f"{path} grew beyond {MAX_ELEMENT_FILE_BYTES} bytes while read")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ElementFileError(f"{path} is not text (byte {exc.start} is "
                               f"0x{data[exc.start]:02X}); expected a TLE (2/3-line) or OMM "
                               "JSON text file") from None


def _file_kind(mode: int) -> str:
    for test, name in ((stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISFIFO, "a FIFO"), (stat.S_ISDIR, "a directory"),
                       (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return "not a regular file"


def load_tle_file(path: str | Path) -> list[TleRecord]:
    """Read a TLE (2- or 3-line) or OMM JSON file; the format is told from the content.

    Raises ElementFileError when the path is no element file to read (read_element_text),
    TleFormatError / OmmFormatError naming the file and the line or record.
    """
    path = Path(path)
    text = read_element_text(path)
    if text.lstrip().startswith(("[", "{")):
        from catalogs.omm import parse_omm_json

        return parse_omm_json(text, source=path.name)
    return parse_tle_text(text, source=path.name)


def select_satellite(records: list[TleRecord], query: str) -> TleRecord:
    """Return the record whose name (case-insensitive) or catalog number matches *query*.

    CelesTrak names a satellite ``NAME (ALIAS)``, e.g. ``ISS (ZARYA)``: either part alone
    matches too. A short name shared by several records (``ISS (ZARYA)``, ``ISS (NAUKA)``:
    modules of one docked station, at one place) picks the oldest object, the lowest
    catalog number. Raises UnknownSatellite (a KeyError) with close names.
    """
    q = " ".join(query.split()).lower()
    for rec in records:
        if rec.name.strip().lower() == q or (q.isdigit() and rec.satnum == int(q)):
            return rec
    by_part = [rec for rec in records if q in _name_parts(rec.name)]
    if by_part:
        return min(by_part, key=lambda rec: rec.satnum)
    import difflib

    close = difflib.get_close_matches(query.upper(), [r.name.upper() for r in records], n=3)
    raise UnknownSatellite(query, close)


def _name_parts(name: str) -> set[str]:
    """Return the lower-case short names of ``NAME (ALIAS)``: {"iss", "zarya"} for ISS (ZARYA)."""
    head, sep, tail = name.strip().partition("(")
    parts = {" ".join(head.split()).lower()}
    if sep and tail.endswith(")"):
        parts.add(" ".join(tail[:-1].split()).lower())
    return parts - {""}


def epoch_age_days(record: TleRecord, when_utc: datetime) -> float:
    """Return (when_utc - epoch) in days; *when_utc* naive datetimes are taken as UTC."""
    if when_utc.tzinfo is None:
        when_utc = when_utc.replace(tzinfo=UTC)
    return (when_utc - record.epoch_utc).total_seconds() / 86400.0


def check_epoch(record: TleRecord, when_utc: datetime, *,
                max_age_days: float = MAX_EPOCH_AGE_DAYS) -> float:
    """Warn (TleEpochWarning) if *when_utc* is more than *max_age_days* from the epoch.

    Returns the signed age in days (positive: elements older than the time used).
    """
    age = epoch_age_days(record, when_utc)
    if math.fabs(age) > max_age_days:
        side = "after" if age > 0 else "before"
        warnings.warn(
            f"{record.name} ({record.source or 'elements'}): time used is {abs(age):.1f} days "
            f"{side} the TLE epoch {record.epoch_utc:%Y-%m-%d %H:%M} UTC (limit {max_age_days:g}); "
            "positions may be off by kilometres -- load fresh elements",
            TleEpochWarning,
            stacklevel=2,
        )
    return age
