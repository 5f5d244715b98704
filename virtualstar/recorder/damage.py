"""Damaged files of a Parquet store: how they are found, named, read around and set aside.

A store's files can be damaged by a full disk, a bad sector, a copy cut short or a careless
hand. The rules (docs/recorder.md, "Damaged files"):

- a reader names each damaged file in a `DamagedFileWarning`, skips what it cannot read
  (a whole hour when its Parquet footer is gone, one row group when only that one is bad)
  and reports the skipped stretch as a gap whose reason starts with ``damaged``;
- `vs data recover` keeps every readable batch or row group, moves the damaged file aside
  as ``<name>.damaged`` and records the loss in gaps.csv. Nothing is ever deleted.

A journal cut short by a crash (its last batch torn) is not damage: that is how a journal
ends when its writer dies, and `recover` finalizes it as always.
"""

from __future__ import annotations

import re
import warnings
from dataclasses import dataclass
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

__all__ = ["DAMAGED_SUFFIX", "Damage", "DamagedFileWarning", "damaged_reason", "footer_problem",
           "is_torn_tail", "readable_row_groups", "row_group_span", "short_error", "warn_damaged"]

DAMAGED_SUFFIX = ".damaged"
#: The reason of a gap that stands for a damaged file or row group starts with this.
DAMAGED_REASON = "damaged"
#: pyarrow's words for a message cut short at the end of a stream (a torn last batch).
_TORN = re.compile(r"Expected to (?:be able to )?read (\d+) (?:metadata )?bytes")
#: A torn batch claims a plausible size; random bytes in a length field claim a huge one.
_MAX_TORN_MESSAGE_BYTES = 1 << 28


class DamagedFileWarning(UserWarning):
    """A file of a store is damaged: it (or part of it) is skipped, and named here."""


@dataclass(frozen=True)
class Damage:
    """One damaged file (or row group): where, what is wrong, the stretch it covered (µs).

    `from_t_us`/`to_t_us` bound the samples that may be missing: the hour of a file whose
    footer is gone, the statistics of an unreadable row group; -1 when unknown.
    """

    path: Path
    problem: str
    from_t_us: int = -1
    to_t_us: int = -1

    def describe(self, store: Path) -> str:
        """Return one line for a user: the file relative to the store, and the problem."""
        try:
            name = self.path.relative_to(store)
        except ValueError:
            name = self.path
        return f"{name} is damaged ({self.problem})"


def damaged_reason(damage: Damage, store: Path) -> str:
    """Return the reason of the gap that stands for `damage` (gaps.csv, `gaps()`)."""
    return f"{DAMAGED_REASON}: {damage.describe(store)}"


def warn_damaged(damage: Damage, store: Path, what: str) -> None:
    """Warn once that a damaged file is skipped, saying `what` is lost."""
    warnings.warn(f"{damage.describe(store)}: {what}", DamagedFileWarning, stacklevel=3)


def footer_problem(path: Path) -> str | None:
    """Return why the Parquet file's footer cannot be read (truncated, not Parquet), or None."""
    try:
        pq.read_metadata(path)
    except (OSError, pa.ArrowException, ValueError) as exc:
        return short_error(exc)
    return None


def readable_row_groups(path: Path) -> tuple[list[int], list[Damage]]:
    """Return the row groups of a Parquet file that decode, and one Damage per one that
    does not (with its time span from the footer's statistics). The footer must be intact."""
    pf = pq.ParquetFile(path)
    good, bad = [], []
    for i in range(pf.metadata.num_row_groups):
        try:
            pf.read_row_group(i)
        except (OSError, pa.ArrowException, ValueError) as exc:
            lo, hi = _t_span(pf.metadata.row_group(i))
            bad.append(Damage(path, f"row group {i}: {short_error(exc)}", lo, hi))
        else:
            good.append(i)
    return good, bad


def is_torn_tail(exc: BaseException) -> bool:
    """Whether a journal read failed on a message cut short at the end of the file (the
    batch a dying writer was writing), rather than on bytes that are wrong."""
    match = _TORN.search(str(exc))
    return match is not None and int(match.group(1)) <= _MAX_TORN_MESSAGE_BYTES


def row_group_span(pf: pq.ParquetFile, index: int) -> tuple[int, int]:
    """Return (min, max) t_us of a row group from the footer's statistics, (-1, -1) if none."""
    return _t_span(pf.metadata.row_group(index))


def _t_span(row_group: pq.RowGroupMetaData) -> tuple[int, int]:
    st = row_group.column(0).statistics
    if st is None or not st.has_min_max:
        return -1, -1
    return int(st.min), int(st.max)


def short_error(exc: BaseException) -> str:
    """Return an exception's message on one line, at most 160 characters."""
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if len(text) <= 160 else text[:157] + "..."
