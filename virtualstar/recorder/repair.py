"""`vs data recover`'s pass over the finished hours: damaged Parquet files set aside.

Opening a store only looks at each file's footer (cheap); this pass also decodes every
row group, so it reads the whole store once. For each finished hour file
(``samples/<hour>-<session>.parquet``):

- footer gone (a truncated copy, a full disk): nothing in it can be read; the file is
  moved aside as ``<name>.damaged`` and its overview as ``<name>.orphaned`` (an envelope
  without samples would disagree with every full-rate query);
- footer intact but row groups that do not decode: the ones that do are written again as
  the hour's file (and its overview), the original is moved aside as ``<name>.damaged``.

Every loss is appended to gaps.csv (reason ``damaged: ...``, the hour or the row group's
time span). Nothing is deleted.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import pyarrow.parquet as pq

from .damage import DAMAGED_SUFFIX, Damage, damaged_reason, footer_problem, readable_row_groups
from .parquet_journal import WriterLock, append_gap, hour_span_us, session_of, write_hour_files

__all__ = ["ORPHANED_SUFFIX", "RepairReport", "repair_finished_hours"]

ORPHANED_SUFFIX = ".orphaned"


@dataclass
class RepairReport:
    """What the pass found: damaged files moved aside, rows kept from them, the losses."""

    moved: list[tuple[Path, str]] = field(default_factory=list)  # (new name, problem)
    rows_kept: int = 0
    damage: list[Damage] = field(default_factory=list)

    def __str__(self) -> str:
        return "; ".join(f"DAMAGED {p.name.removesuffix(DAMAGED_SUFFIX)} ({problem}): moved "
                         f"aside as {p.name}, its loss recorded as a gap"
                         for p, problem in self.moved)


def repair_finished_hours(store: Path, *, row_group_rows: int, zstd_level: int,
                          overview_bucket_us: int) -> RepairReport:
    """Set aside the damaged hour files of a store, keeping what they still hold.

    Raises StoreError when a live recorder holds the store.
    """
    report = RepairReport()
    lock = WriterLock(store)
    lock.acquire()
    try:
        for f in sorted((store / "samples").glob("*.parquet")):
            overview = store / "overview" / f.name
            problem = footer_problem(f)
            if problem is not None:
                _whole_file(store, f, overview, problem, report)
                continue
            good, bad = readable_row_groups(f)
            if bad:
                _some_row_groups(store, f, overview, good, bad, report, row_group_rows,
                                 zstd_level, overview_bucket_us)
    finally:
        lock.release()
    return report


def _whole_file(store: Path, f: Path, overview: Path, problem: str,
                report: RepairReport) -> None:
    damage = Damage(f, problem, *hour_span_us(f))
    aside = f.with_name(f.name + DAMAGED_SUFFIX)
    os.replace(f, aside)
    if overview.exists():
        os.replace(overview, overview.with_name(overview.name + ORPHANED_SUFFIX))
    append_gap(store, [damage.from_t_us, damage.to_t_us, -1,
                       f"{damaged_reason(damage, store)}; moved aside as {aside.name}",
                       session_of(f)])
    report.moved.append((aside, problem))
    report.damage.append(damage)


def _some_row_groups(store: Path, f: Path, overview: Path, good: list[int],
                     bad: list[Damage], report: RepairReport, row_group_rows: int,
                     zstd_level: int, overview_bucket_us: int) -> None:
    aside = f.with_name(f.name + DAMAGED_SUFFIX)
    os.replace(f, aside)  # first aside: a crash from here on leaves the evidence in place
    source = pq.ParquetFile(aside)
    batches = (batch for i in good for batch in source.read_row_group(i).to_batches())
    done = write_hour_files(batches, f, overview, row_group_rows=row_group_rows,
                            zstd_level=zstd_level, overview_bucket_us=overview_bucket_us)
    if not done.files and overview.exists():
        os.replace(overview, overview.with_name(overview.name + ORPHANED_SUFFIX))
    for damage in bad:
        append_gap(store, [damage.from_t_us, damage.to_t_us, -1,
                           f"{damaged_reason(damage, store)}; moved aside as {aside.name}",
                           session_of(f)])
    report.rows_kept += done.rows
    report.moved.append((aside, ", ".join(d.problem for d in bad)))
    report.damage += bad
