"""PNG plots of a store like the paper's Fig. 6 (whole night, min/max envelope) and
Fig. 7 (the first seconds at full rate): one panel per signal, a shared time axis.

Signals whose name ends in ``position`` are drawn as the change since the first sample
(the paper's "axis position change"), so a drift of radians and a tracking error of
milli-arcseconds both fill their panels.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only: never open a window, never need a display
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .decimation import Envelope  # noqa: E402
from .parquet_store import utc_text  # noqa: E402
from .samples import SampleBlock, SignalInfo  # noqa: E402

__all__ = ["plot_envelope", "plot_window"]

DPI = 110


def _label(info: SignalInfo, relative: bool) -> str:
    unit = f" [{info.unit}]" if info.unit else ""
    return (f"Δ {info.name}" if relative else info.name) + unit


def _relative(info: SignalInfo) -> bool:
    return info.name.endswith("position")


def plot_envelope(env: Envelope, signals: list[SignalInfo], path: str | Path, *,
                  title: str = "") -> Path:
    """Write the min/max envelope of `signals` over hours since its first bucket as a PNG."""
    path = Path(path)
    fig, axes = plt.subplots(len(signals), 1, figsize=(10, 2.3 * len(signals) + 0.8),
                             sharex=True, squeeze=False)
    if len(env):
        hours = (env.t_us - env.t_us[0]) / 3.6e9
        for ax, info in zip(axes[:, 0], signals, strict=True):
            lo, hi = env.mins[info.name].astype(float), env.maxs[info.name].astype(float)
            if _relative(info):
                ref = lo[np.isfinite(lo)][0] if np.isfinite(lo).any() else 0.0
                lo, hi = lo - ref, hi - ref
            ax.fill_between(hours, lo, hi, step="post", linewidth=0.6, color="tab:blue")
            ax.set_ylabel(_label(info, _relative(info)), fontsize=8)
            ax.grid(alpha=0.3)
        start = utc_text(int(env.t_us[0]))
        axes[-1, 0].set_xlabel(f"hours since {start} (mount time); min/max per "
                               f"{env.bucket_us / 1e6:g} s bucket")
    fig.suptitle(title or "Whole recording: min/max envelope", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path


def plot_window(block: SampleBlock, signals: list[SignalInfo], path: str | Path, *,
                title: str = "") -> Path:
    """Write every sample of `block` (a short window at full rate) as a PNG."""
    path = Path(path)
    fig, axes = plt.subplots(len(signals), 1, figsize=(10, 2.3 * len(signals) + 0.8),
                             sharex=True, squeeze=False)
    if len(block):
        secs = (block.t_us - block.t_us[0]) / 1e6
        for ax, info in zip(axes[:, 0], signals, strict=True):
            v = block.columns[info.name].astype(float)
            if _relative(info):
                v = v - v[0]
            ax.plot(secs, v, linewidth=0.7, color="tab:blue")
            ax.set_ylabel(_label(info, _relative(info)), fontsize=8)
            ax.grid(alpha=0.3)
        axes[-1, 0].set_xlabel(f"seconds since {utc_text(int(block.t_us[0]))} (mount time); "
                               f"{len(block)} samples per signal")
    fig.suptitle(title or "Full rate", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path
