"""Residual plots of a fit as a PNG: residuals against azimuth and elevation, sky map."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .fitting import FitResult
from .runs import PointingRun


def plot_residuals(run: PointingRun, result: FitResult, path: str | Path) -> None:
    """Write a PNG with ΔA·cos E and ΔE against A and E, and a sky map of residual vectors.

    Rejected observations are drawn as red crosses. Uses matplotlib's Agg backend (no display).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    used = result.used
    rs, re = result.residual_s_arcsec, result.residual_e_arcsec
    az, el = np.mod(run.obs_az_deg, 360.0), run.obs_el_deg
    fig = plt.figure(figsize=(11, 12))
    grid = fig.add_gridspec(3, 2, height_ratios=[1.0, 1.0, 2.0])
    title = (f"{Path(result.source).name}: {' '.join(result.terms)} — sky RMS "
             f"{result.sky_rms_arcsec:.2f}″, PSD {result.psd_arcsec:.2f}″, "
             f"N={result.n_obs}, rejected {result.n_rejected}")
    fig.suptitle(title, fontsize=10)
    panels = [(grid[0, 0], az, rs, "azimuth (deg)", "ΔA·cos E (arcsec)"),
              (grid[0, 1], az, re, "azimuth (deg)", "ΔE (arcsec)"),
              (grid[1, 0], el, rs, "elevation (deg)", "ΔA·cos E (arcsec)"),
              (grid[1, 1], el, re, "elevation (deg)", "ΔE (arcsec)")]
    for cell, xv, yv, xlabel, ylabel in panels:
        ax = fig.add_subplot(cell)
        ax.axhline(0.0, color="0.6", lw=0.8)
        ax.plot(xv[used], yv[used], "o", ms=3)
        ax.plot(xv[~used], yv[~used], "x", color="red", ms=5)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
    ax = fig.add_subplot(grid[2, :])
    a_rad, rho = np.radians(az), 90.0 - el  # zenith distance, degrees, north up, east right
    px, py = rho * np.sin(a_rad), rho * np.cos(a_rad)
    scale = 5.0 / max(result.sky_rms_arcsec, 1e-9)  # an RMS-long residual is drawn 5° long
    # ΔS along increasing azimuth, ΔE towards the zenith (centre).
    vx = scale * (rs * np.cos(a_rad) - re * np.sin(a_rad))
    vy = scale * (-rs * np.sin(a_rad) - re * np.cos(a_rad))
    for z in (30.0, 60.0, 90.0):
        circle = np.radians(np.linspace(0.0, 360.0, 181))
        ax.plot(z * np.sin(circle), z * np.cos(circle), color="0.8", lw=0.8)
    ax.plot(px[used], py[used], ".", ms=3, color="C0")
    ax.quiver(px[used], py[used], vx[used], vy[used], angles="xy", scale_units="xy",
              scale=1.0, width=0.003)
    ax.plot(px[~used], py[~used], "x", color="red")
    ax.text(0, 92, "N", ha="center")
    ax.text(92, 0, "E", va="center")
    ax.set_aspect("equal")
    ax.set_xlim(-100, 100)
    ax.set_ylim(-100, 100)
    ax.set_axis_off()
    ax.set_title(f"residual vectors on the sky (5° arrow = {result.sky_rms_arcsec:.2f}″); "
                 "circles at E = 60°, 30°, 0°", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
