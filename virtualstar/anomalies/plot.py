"""`vs data anomalies --plot`: each detector's score over time, flagged stretches shaded."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only: never open a window
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from virtualstar.recorder.parquet_store import utc_text  # noqa: E402

from .report import AnomalyReport  # noqa: E402

__all__ = ["plot_report"]

DPI = 110


def plot_report(report: AnomalyReport, path: str | Path, *, title: str = "") -> Path:
    """Write a PNG: one panel per detector trace (score; 1 = flagging limit), anomalies shaded."""
    path = Path(path)
    traces = report.traces or []
    fig, axes = plt.subplots(max(1, len(traces)), 1, figsize=(10, 1.6 * max(1, len(traces)) + 1),
                             sharex=True, squeeze=False)
    t0 = report.from_t_us
    for ax, trace in zip(axes[:, 0], traces, strict=False):
        hours = (trace.t_us - t0) / 3.6e9
        ax.step(hours, np.nan_to_num(trace.score, nan=0.0), where="post", linewidth=0.7)
        ax.axhline(1.0, color="tab:red", linewidth=0.6, linestyle="--")
        ax.set_ylabel(trace.name, fontsize=8)
        ax.set_yscale("symlog", linthresh=1.0)
        ax.grid(alpha=0.3)
        ax.axvspan((report.reference_t_us[0] - t0) / 3.6e9,
                   (report.reference_t_us[1] - t0) / 3.6e9, color="tab:green", alpha=0.12)
        for a in report.anomalies:
            label = f"{a.axis} {a.kind}".strip()
            if trace.name == label or (a.kind == "clock" and trace.name == "clock"):
                ax.axvspan((a.start_us - t0) / 3.6e9, (a.end_us - t0) / 3.6e9,
                           color="tab:red", alpha=0.25)
    axes[-1, 0].set_xlabel(f"hours since {utc_text(t0)} (mount time); green: reference "
                           "stretch, red: flagged; score 1 = flagging limit")
    fig.suptitle(title or f"{len(report.anomalies)} anomalies", fontsize=10)
    # fixed margins (inches) instead of tight_layout, whose measuring draw pass cost as
    # much as the drawing itself (0.25 s of a plot): the panels' labels are short
    height_in = fig.get_figheight()
    fig.subplots_adjust(left=0.08, right=0.98, bottom=0.55 / height_in,
                        top=1.0 - 0.45 / height_in, hspace=0.12)
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path
