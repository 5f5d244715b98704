"""A plan as a picture: every block's target elevation over the night, twilight shaded."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from virtualstar.astro import EarthOrientation, Site, UtcTimes

from .program import Program
from .scheduler import Plan
from .sky import NightGrid, load_target_satellite, target_skies

__all__ = ["plot_plan", "plot_run"]

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
    planned = [by_name[n] for n in dict.fromkeys(b.target for b in plan.blocks)]
    sidereal = [t for t in planned if not t.is_satellite]
    # every sidereal target at once: ERFA's per-time work is shared (observe_stars)
    el_of = {t.name: s.el_deg for t, s in
             zip(sidereal, target_skies(sidereal, grid, site, eop, _no_zones()), strict=True)
             if s.el_deg is not None}
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for k, target in enumerate(planned):
        name = target.name
        colour = colours[k % len(colours)]
        if target.is_satellite:
            sat = load_target_satellite(target)
            for b in (b for b in plan.blocks if b.target == name):
                t = np.arange(b.start_us, b.end_us + 1, 1_000_000, dtype=np.int64)
                el = np.degrees(observe_mount_times(sat, t, site, eop).el_rad)
                ax.plot((t - grid.t_us[0]) / 3.6e9, el, color=colour, lw=3,
                        label=name if b.repeat == 1 else None)
            continue
        el = el_of.get(name)
        if el is None:  # never where it may be observed: no curve to draw
            continue
        ax.plot(hours, el, color=colour, lw=0.8, alpha=0.6)
        for b in (b for b in plan.blocks if b.target == name):
            sel = (grid.t_us >= b.start_us) & (grid.t_us <= b.end_us)
            ax.plot(hours[sel], el[sel], color=colour, lw=3.5,
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
    return _save(fig, path)


def _no_zones():
    from virtualstar.astro import AvoidanceZones

    return AvoidanceZones(sun_radius_deg=0.0)


_OUTCOME_COLOURS = {"done": "tab:green", "degraded": "tab:brown", "late": "tab:olive",
                    "missed": "tab:grey", "faulted": "tab:red", "stopped": "tab:orange"}
# per block: (figure key, label, colour); on target first: it is what the sky saw
_ERROR_BARS = (("on_target", "on target (boresight vs target)", "tab:green"),
               ("encoder", "following (encoders vs demand)", "tab:blue"),
               ("on_sky", "on the sky (with the clock)", "tab:purple"))


def plot_run(run: dict, path: str | Path) -> Path:
    """Write a run's PNG: planned and observed blocks per target against UTC (coloured by
    outcome, re-plans marked), and each block's error on target, following error and
    on-sky error, with the peak planned deviation apart (a keyhole)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    records = [*run.get("done_before", []), *run["records"]]
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(11, 7), height_ratios=[1.2, 1])
    if not records:
        top.text(0.5, 0.5, "no block was run", ha="center", transform=top.transAxes)
    t0 = min((r["planned_start_us"] for r in records), default=0)
    names = list(dict.fromkeys(r["target"] for r in records))
    for r in records:
        y = names.index(r["target"])
        a, b = (r["planned_start_us"] - t0) / 3.6e9, (r["planned_end_us"] - t0) / 3.6e9
        top.barh(y, b - a, left=a, height=0.7, fill=False, edgecolor="0.5", lw=0.8)
        if r.get("start_us") is not None and r.get("end_us") is not None:
            a, b = (r["start_us"] - t0) / 3.6e9, (r["end_us"] - t0) / 3.6e9
            top.barh(y, max(b - a, 1e-4), left=a, height=0.5,
                     color=_OUTCOME_COLOURS.get(r["outcome"], "k"))
        else:
            top.plot([a], [y], "x", color=_OUTCOME_COLOURS.get(r["outcome"], "k"))
    for rp in run.get("replans", []):
        top.axvline((rp["at_us"] - t0) / 3.6e9, color="tab:red", ls="--", lw=0.8)
    top.set_yticks(range(len(names)), names)
    top.set_ylim(-0.6, len(names) + 0.4)  # room for the legend above the last row
    top.set_xlabel(f"hours after {UtcTimes.from_unix_us(int(t0)).iso(0)[0]} UTC" if records
                   else "hours")
    handles = [plt.Rectangle((0, 0), 1, 1, color=c) for c in _OUTCOME_COLOURS.values()]
    top.legend(handles + [plt.Line2D([], [], color="tab:red", ls="--")],
               [*_OUTCOME_COLOURS, "re-plan"], fontsize=8, ncol=7, loc="upper right")
    s = run.get("summary", {})
    top.set_title(f"{run.get('program', '')}: {run.get('state', '')} — {s.get('done', 0)} done, "
                  f"{s.get('degraded', 0)} degraded, {s.get('late', 0)} late, "
                  f"{s.get('missed', 0)} missed, {s.get('faulted', 0)} faulted; "
                  f"{s.get('priority_weighted_hours', 0.0):.2f} priority-weighted hours on "
                  "target (outline: planned, filled: observed)", fontsize=10)
    observed = [r for r in records if r.get("encoder_rms_arcsec") is not None]
    x = np.arange(len(observed))
    labels = [f"{r['target']} #{r['repeat']}" + (f"\n{r['outcome']}" if r["outcome"] != "done"
                                                 else "") for r in observed]
    width = 0.8 / len(_ERROR_BARS)
    for k, (key, label, colour) in enumerate(_ERROR_BARS):
        off = (k - (len(_ERROR_BARS) - 1) / 2) * width
        rms = [r.get(f"{key}_rms_arcsec") or np.nan for r in observed]
        peak = [r.get(f"{key}_peak_arcsec") or np.nan for r in observed]
        bottom.bar(x + off, rms, width=width, color=colour, label=f"{label}: RMS")
        bottom.plot(x + off, peak, "v", color=colour, label="… peak")
    planned = [r.get("planned_deviation_peak_arcsec") or np.nan for r in observed]
    if np.any(np.asarray(planned) > 0.01):
        bottom.plot(x, planned, "D", mfc="none", color="tab:red",
                    label="planned deviation peak (a keyhole), apart")
    bottom.set_yscale("log")
    bottom.set_ylabel("error [arcsec]")
    bottom.set_xticks(x, labels, rotation=45, ha="right", fontsize=8)
    bottom.grid(True, axis="y", alpha=0.3)
    if observed:
        bottom.legend(fontsize=7, ncol=4)
    return _save(fig, path)


def _save(fig, path: str | Path) -> Path:
    import matplotlib.pyplot as plt

    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
