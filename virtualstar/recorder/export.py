"""Export a store (or a window of it) to CSV and to MATLAB .mat files.

CSV: header ``t_us,<names>``; floats are written as the shortest text that reads back to
the same double, so a CSV round trip is exact. MATLAB: one variable per signal with dots
turned into underscores (``axis_az_position``), ``t_us`` as int64, and the original
names and units in ``names``/``units`` cell arrays (scipy.io.savemat, v5, compressed).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import TextIO

import numpy as np

from .exceptions import StoreError
from .samples import SampleBlock, SignalInfo

__all__ = ["mat_name", "write_csv", "write_mat"]


def mat_name(name: str) -> str:
    """Return a MATLAB variable name for a signal name (``axis.az.position`` → ``axis_az_position``)."""
    out = re.sub(r"[^A-Za-z0-9_]", "_", name)
    if not out or not out[0].isalpha():
        out = "s_" + out
    return out[:63]


def write_csv(blocks, names: list[str], path: str | Path | TextIO) -> int:
    """Write the SampleBlocks of `blocks` (an iterable, in time order) as CSV; return the rows.

    `path` is a file name or an open text file (e.g. sys.stdout).
    """
    if not isinstance(path, str | Path):
        return _write_csv_rows(blocks, names, path)
    try:
        with Path(path).open("w", newline="") as f:
            return _write_csv_rows(blocks, names, f)
    except OSError as exc:
        raise StoreError(f"cannot write {path}: {exc.strerror}") from None


def _write_csv_rows(blocks, names: list[str], f: TextIO) -> int:
    rows = 0
    f.write(",".join(["t_us", *names]) + "\n")
    for block in blocks:
        cols = [block.t_us.tolist()]
        for n in names:
            v = block.columns[n]
            cols.append([repr(x) for x in v.tolist()] if v.dtype.kind == "f" else v.tolist())
        f.writelines(",".join(map(str, row)) + "\n" for row in zip(*cols, strict=True))
        rows += len(block)
    return rows


def write_mat(block: SampleBlock, signals: list[SignalInfo], path: str | Path) -> int:
    """Write `block` as a MATLAB .mat file (v5, compressed); return the rows."""
    from scipy.io import savemat

    path = Path(path)
    data: dict[str, object] = {"t_us": np.asarray(block.t_us, dtype=np.int64)}
    used = {"t_us", "names", "units"}
    for s in signals:
        key = mat_name(s.name)
        while key in used:
            key = key + "_"
        used.add(key)
        data[key] = np.asarray(block.columns[s.name])
    data["names"] = np.array([s.name for s in signals], dtype=object)
    data["units"] = np.array([s.unit for s in signals], dtype=object)
    try:
        savemat(path, data, do_compression=True, oned_as="column")
    except OSError as exc:
        raise StoreError(f"cannot write {path}: {exc.strerror}") from None
    return len(block)
