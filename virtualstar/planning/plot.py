"""A plan as a picture: every block's target elevation over the night, twilight shaded."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from virtualstar.astro import EarthOrientation, Site, UtcTimes

from .program import Program
from .scheduler import Plan
from .sky import NightGrid, load_target_satellite, target_sky

__all__ = ["plot_plan"]

_TWILIGHT = [(0.0, -6.0, 0.10), (-6.0, -12.0, 0.18), (-12.0, -18.0, 0.26), (-18.0, -90.0, 0.34)]


def plot_plan(plan: Plan, program: Program, site: Site, path: str | Path,
              eop: EarthOrientation | None = None) -> Path:
    """Write the plan's PNG to `path`: elevation of each planned target against UTC, the
    blocks drawn thick over their curves, twilight shaded; return the path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from virtualstar.astro import observe_mount_times

    eop = eop or EarthOrientation.from_astropy_iers_data()
    grid = NightGrid.build(plan.start_us, plan.end_us, site, eop, 120.0)
    hours = (grid.t_us - grid.t_us[0]) / 3.6e9
    fig, ax = plt.subplots(figsize=(11, 5.5))
    for hi, lo, alpha in _TWILIGHT:
        band = (grid.sun_el_deg <= hi) & (grid.sun_el_deg > lo)
        ax.fill_between(hours, 0, 90, where=band, color="midnightblue", alpha=alpha, lw=0,
                        step="mid")
    by_name = {t.name: t for t in program.targets}
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for k, name in enumerate(dict.fromkeys(b.target for b in plan.blocks)):
        target = by_name[name]
        colour = colours[k % len(colours)]
        if target.is_satellite:
            sat = load_target_satellite(target)
            for b in (b for b in plan.blocks if b.target == name):
                t = np.arange(b.start_us, b.end_us + 1, 1_000_000, dtype=np.int64)
                el = np.degrees(observe_mount_times(sat, t, site, eop).el_rad)
                ax.plot((t - grid.t_us[0]) / 3.6e9, el, color=colour, lw=3,
                        label=name if b.repeat == 1 else None)
            continue
        sky = target_sky(target, grid, site, eop, _no_zones())
        ax.plot(hours, sky.el_deg, color=colour, lw=0.8, alpha=0.6)
        for b in (b for b in plan.blocks if b.target == name):
            sel = (grid.t_us >= b.start_us) & (grid.t_us <= b.end_us)
            ax.plot(hours[sel], sky.el_deg[sel], color=colour, lw=3.5,
                    label=name if b.repeat == 1 else None)
    ax.set_ylim(0, 90)
    ax.set_xlim(hours[0], hours[-1])
    ticks = np.arange(0, hours[-1] + 1e-9, 1.0)
    ax.set_xticks(ticks)
    ax.set_xticklabels([UtcTimes.from_unix_us(int(grid.t_us[0] + h * 3.6e9)).iso(0)[0][11:16]
                        for h in ticks])
    ax.set_xlabel(f"UTC, night of {UtcTimes.from_unix_us(plan.start_us).iso(0)[0][:10]}")
    ax.set_ylabel("elevation [deg]")
    ax.set_title(f"{plan.program}: {len(plan.blocks)} blocks, "
                 f"{plan.weighted_hours:.2f} priority-weighted hours, {len(plan.left_out)} "
                 "targets left out (darker: deeper twilight)")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper right", fontsize=8, ncol=2)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _no_zones():
    from virtualstar.astro import AvoidanceZones

    return AvoidanceZones(sun_radius_deg=0.0)
