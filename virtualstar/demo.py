"""The VirtualStar demo: one process, lockstep simulated time, the embedded emulator, the real VSS.

`run_demo()` places the emulator's clock a little before a high ISS pass over
the site (found with the pass predictor from the bundled TLE), starts the
VirtualStar Server on it, and as an API client (in the same process, no socket):
slews to a bright star, tracks it sidereally, then tracks the ISS through the
whole pass. It returns the per-phase figures (slew time; RMS and peak of the error on
target — the boresight against the target's true place —, of the encoders' following
error and on the sky; the planned deviation apart) and writes a PNG of the errors.

The emulator and the server share one `LockstepClock`: mount time advances only
when the server has done the work due, so the figures are the same on every run
and every host; only the wall time differs. `speed` caps the pace (×N real time);
None runs as fast as the CPU allows.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from virtualstar.astro import (
    EarthOrientation,
    Satellite,
    Site,
    UtcTimes,
    iso_utc,
    load_site,
    observe_mount_times,
    resolve_target,
    satellite_passes,
)

__all__ = ["DemoConfig", "DemoPhase", "DemoResult", "find_demo_pass", "run_demo"]

STAR_CHOICES = ("Vega", "Arcturus", "Capella", "Deneb", "Altair", "Sirius", "Canopus", "Rigel")


@dataclass(frozen=True)
class DemoConfig:
    """What the demo does (mount seconds unless said otherwise)."""

    speed: float | None = None  # None: as fast as the CPU allows; X: at most X times real time
    sidereal_s: float = 30.0
    min_culmination_deg: float = 60.0
    before_pass_s: float = 210.0  # clock placed this long before the pass rises
    out_dir: Path = Path("demo-output")
    site: Site | None = None
    tle_set: str = "stations"
    satellite: str = "ISS"


@dataclass
class DemoPhase:
    """One phase over [from_us, to_us] (arcsec); slew time if it is a slew.

    `rms_arcsec`/`peak_arcsec`: the encoders' following error (vs the demand sent);
    `on_target_*`: the boresight against the target's true place (what the sky saw);
    `planned_deviation_peak_arcsec`: the demand against that place (a keyhole), apart.
    """

    name: str
    target: str
    rms_arcsec: float
    peak_arcsec: float
    from_us: int
    to_us: int
    slew_time_s: float | None = None
    on_sky_rms_arcsec: float | None = None  # on target with clock offset × target rate
    on_sky_peak_arcsec: float | None = None
    clock_offset_us: int | None = None  # the largest mount clock offset during the phase
    on_target_rms_arcsec: float | None = None
    on_target_peak_arcsec: float | None = None
    off_target_s: float | None = None
    planned_deviation_peak_arcsec: float | None = None

    def as_dict(self) -> dict[str, Any]:
        return {"name": self.name, "target": self.target, "rms_arcsec": self.rms_arcsec,
                "peak_arcsec": self.peak_arcsec, "duration_s": (self.to_us - self.from_us) / 1e6,
                "slew_time_s": self.slew_time_s, "on_sky_rms_arcsec": self.on_sky_rms_arcsec,
                "on_sky_peak_arcsec": self.on_sky_peak_arcsec,
                "clock_offset_us": self.clock_offset_us,
                "on_target_rms_arcsec": self.on_target_rms_arcsec,
                "on_target_peak_arcsec": self.on_target_peak_arcsec,
                "off_target_s": self.off_target_s,
                "planned_deviation_peak_arcsec": self.planned_deviation_peak_arcsec}


@dataclass
class DemoResult:
    phases: list[DemoPhase] = field(default_factory=list)
    plot: str | None = None
    wall_s: float = 0.0
    pass_info: dict[str, Any] = field(default_factory=dict)
    series: dict[str, list] = field(default_factory=dict)
    time_sync: dict[str, Any] = field(default_factory=dict)
    spans: list[tuple[str, int, int]] = field(default_factory=list)  # what the mount did, when
    encoder_quantum_arcsec: float | None = None

    def as_dict(self) -> dict[str, Any]:
        return {"phases": [p.as_dict() for p in self.phases], "plot": self.plot,
                "wall_s": self.wall_s, "pass": self.pass_info, "time_sync": self.time_sync}


def find_demo_pass(site: Site, sat: Satellite, min_culmination_deg: float) -> tuple[int, int, float]:
    """Return (rise µs, set µs, culmination deg) of the first pass culminating above the minimum
    within three days of the element set's epoch (the highest one if none does)."""
    start = sat.epoch.shifted(-3600.0) if hasattr(sat, "epoch") else UtcTimes.now()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        passes = satellite_passes(sat, site, start, start.shifted(3 * 86400.0), min_el_deg=5.0)
    full = [p for p in passes if p.rise is not None and p.set is not None]
    if not full:
        raise RuntimeError(f"{sat.name} has no pass above 5 deg at {site.name} near its epoch")
    good = [p for p in full if p.culmination.el_deg >= min_culmination_deg]
    p = good[0] if good else max(full, key=lambda q: q.culmination.el_deg)
    return (int(p.rise.utc.to_unix_us()[0]), int(p.set.utc.to_unix_us()[0]), p.culmination.el_deg)


def pick_star(site: Site, t_us: int) -> str:
    """Return the first bright star of STAR_CHOICES between 25° and 75° elevation at t_us."""
    eop = EarthOrientation.from_astropy_iers_data()
    for name in STAR_CHOICES:
        obs = observe_mount_times(resolve_target(name), np.array([t_us], np.int64), site, eop)
        if 25.0 <= math.degrees(obs.el_rad[0]) <= 75.0:
            return name
    return STAR_CHOICES[0]


def run_demo(config: DemoConfig = DemoConfig(),
                   say: Callable[[str], None] = lambda text: None) -> DemoResult:
    """Run the whole demo on a lockstep event loop of its own; return its phases and plot path."""
    from virtualstar.lockstep import LockstepClock, run_lockstep

    wall0 = time.perf_counter()
    site = config.site or load_site()
    sat, tle_text = _demo_satellite(config)
    rise_us, set_us, culm = find_demo_pass(site, sat, config.min_culmination_deg)
    start_us = rise_us - int(config.before_pass_s * 1e6)
    clock = LockstepClock(start_us, pace=config.speed)
    result = run_lockstep(_run(config, site, sat, tle_text, rise_us, set_us, culm, say, clock),
                          clock)
    result.plot = str(_plot(result, config.out_dir))
    result.wall_s = time.perf_counter() - wall0
    return result


def _demo_satellite(config: DemoConfig) -> tuple[Satellite, str]:
    from catalogs import load_tle_file, sample_tle_path, select_satellite

    tle_path = sample_tle_path(config.tle_set)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        records = load_tle_file(tle_path)
    records = [r for r in records if config.satellite.lower() in r.name.lower()] or records
    record = select_satellite(records, records[0].name)
    return Satellite.from_record(record), Path(tle_path).read_text(encoding="utf-8")


async def _run(config: DemoConfig, site: Site, sat: Satellite, tle_text: str, rise_us: int,
               set_us: int, culm: float, say: Callable[[str], None], clock) -> DemoResult:
    from virtualstar.launcher import embedded_vss

    start_us = clock.now_us
    star = pick_star(site, start_us + 30_000_000)
    result = DemoResult(pass_info={"satellite": sat.name, "rise_utc": iso_utc(rise_us),
                                   "set_utc": iso_utc(set_us), "culmination_deg": culm})
    pace = "as fast as the CPU allows" if config.speed is None else f"up to x{config.speed:g}"
    say(f"simulated clock {iso_utc(start_us)} in lockstep ({pace}), site {site.name}; "
        f"{sat.name} rises {iso_utc(rise_us)}, culminates at {culm:.1f}°")
    async with embedded_vss(clock=clock, site=site) as vss:
        vs = vss.client()
        settle_s = vss.server.telescope.config.settle_s
        say(f"slewing to {star}, then tracking it for {config.sidereal_s:g} s")
        op = await vs.request("track", {"star": star, "duration_s": config.sidereal_s,
                                        "wait": True})
        info = op["info"]
        landed = info["landed_us"]
        landing = (await vs.request("errors", {"from_us": landed,
                                               "to_us": landed + int(settle_s * 1e6)}))["stats"]
        result.phases.append(_phase(f"slew to {star} (landing)", star, landing,
                                    slew_time_s=info["slew_time_s"]))
        say(f"landed after {info['slew_time_s']:.1f} s (within {info['landing_error_arcsec']:.3f}″ "
            f"of {star}); tracked {config.sidereal_s:g} s")
        sidereal = (await vs.request("errors", {"from_us": info["tracking_from_us"],
                                                "to_us": info["tracking_to_us"]}))["stats"]
        result.phases.append(_phase(f"sidereal tracking {star}", star, sidereal))
        result.spans += [(f"slew to {star}", info["slew_from_us"], landed),
                         ("settle", landed, info["tracking_from_us"]),
                         (f"track {star}", info["tracking_from_us"], info["tracking_to_us"])]
        star_end = info["tracking_to_us"]
        say(f"waiting for {sat.name} (pass {iso_utc(rise_us)} .. {iso_utc(set_us)})")
        op = await vs.request("track", {"tle": tle_text, "sat": sat.name, "wait": True})
        info = op["info"]
        passing = (await vs.request("errors", {"from_us": info["tracking_from_us"],
                                               "to_us": info["tracking_to_us"]}))["stats"]
        result.phases.append(_phase(f"satellite pass {sat.name}", sat.name, passing))
        result.spans += [("hold", star_end, info["slew_from_us"]),
                         ("slew, wait for the pass", info["slew_from_us"],
                          info["tracking_from_us"]),
                         (f"{sat.name.split(' (')[0]} pass", info["tracking_from_us"],
                          info["tracking_to_us"])]
        result.encoder_quantum_arcsec = await _encoder_quantum_arcsec(vss)
        result.pass_info.update({k: info.get(k) for k in (
            "keyhole", "keyhole_max_error_arcsec", "max_az_rate_deg_s")})
        result.series = (await vs.request("errors", {"series": True, "max_points": 4000,
                                                     "from_us": start_us}))["series"]
        result.time_sync = (await vs.request("status"))["time_sync"]
    return result


def _phase(name: str, target: str, stats: dict[str, Any], *,
           slew_time_s: float | None = None) -> DemoPhase:
    return DemoPhase(name, target, stats["rms_arcsec"], stats["peak_arcsec"], stats["from_us"],
                     stats["to_us"], slew_time_s, stats["on_sky_rms_arcsec"],
                     stats["on_sky_peak_arcsec"], stats["clock_offset_us"],
                     stats.get("on_target_rms_arcsec"), stats.get("on_target_peak_arcsec"),
                     stats.get("off_target_s"), stats.get("planned_deviation_peak_arcsec"))


async def _encoder_quantum_arcsec(vss) -> float:
    """One count of the azimuth encoder on the sky (arcsec), read from the emulator."""
    client = await vss.emulator.connect_in_memory(name="demo")
    try:
        bits = (await client.read(["axis.az.encoder_bits"]))["axis.az.encoder_bits"]
    finally:
        await client.close()
    return 360.0 * 3600.0 / 2.0 ** float(bits)


_SPAN_COLOURS = {"slew": "tab:orange", "settle": "tab:purple", "track": "tab:green",
                 "hold": "tab:gray", "wait": "tab:orange", "pass": "tab:blue"}


def _plot(result: DemoResult, out_dir: Path) -> Path:
    """Tracking error over the whole demo: every phase labelled, per axis, and the encoder
    quantum (below it the error is the encoders' resolution, not the tracking)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    series = result.series
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / "tracking-error.png"
    t = np.asarray(series["t_us"], dtype=np.int64)
    t0 = int(t[0]) if t.size else 0
    x = (t - t0) / 1e6
    fig, ax = plt.subplots(figsize=(11, 5))
    total_s = max((x[-1] - x[0]) if x.size else 1.0, 1.0)
    row = 0
    for label, a, b in result.spans:
        colour = next((c for key, c in _SPAN_COLOURS.items() if key in label), "tab:gray")
        ax.axvspan((a - t0) / 1e6, (b - t0) / 1e6, alpha=0.13, color=colour, lw=0)
        short = (b - a) / 1e6 < 0.03 * total_s
        ax.text((a - t0) / 1e6 + (0 if short else (b - a) / 2e6), 0.98 - 0.05 * row, label,
                ha="left" if short else "center", va="top", fontsize=8, color=colour,
                transform=ax.get_xaxis_transform())
        row = (row + 1) % 4
    floor = 1e-4

    def values(key: str) -> np.ndarray:  # None (no target followed) → a gap in the line
        return np.maximum(np.array([np.nan if v is None else v for v in series[key]], float),
                          floor)

    # on target (the truth) on top; it equals the following error wherever nothing is planned
    ax.semilogy(x, values("on_target_rms_arcsec"), lw=2.4, color="tab:green", alpha=0.55,
                zorder=5, label="on target RMS per 0.1 s (boresight vs the target's true place)")
    ax.semilogy(x, values("planned_deviation_arcsec"), lw=0.6, color="tab:pink", zorder=4,
                label="planned deviation, peak per 0.1 s (demand vs true place)")
    ax.semilogy(x, np.maximum(series["peak_arcsec"], floor), lw=0.6, color="tab:red",
                label="following error peak per 0.1 s (encoders vs demand)")
    ax.semilogy(x, np.maximum(series["rms_arcsec"], floor), lw=0.9, color="black",
                label="following error RMS per 0.1 s")
    ax.semilogy(x, np.maximum(series["az_rms_arcsec"], floor), lw=0.6, color="tab:cyan",
                label="azimuth RMS (× cos el)")
    ax.semilogy(x, np.maximum(series["el_rms_arcsec"], floor), lw=0.6, color="tab:olive",
                label="elevation RMS")
    if result.encoder_quantum_arcsec:
        q = result.encoder_quantum_arcsec
        ax.axhline(q, color="tab:brown", ls="--", lw=0.8)
        ax.text(0.005, q * 1.1, f"one encoder count = {q:.4f}″: below it, the encoders' "
                "resolution, not tracking", transform=ax.get_yaxis_transform(), fontsize=7,
                color="tab:brown", va="bottom")
    ax.set_xlabel(f"mount time since {iso_utc(t0)} UTC [s]")
    ax.set_ylabel("error on the sky [arcsec]")
    ax.set_title("VirtualStar demo: errors through slews, sidereal tracking and an "
                 "ISS pass (lockstep simulated time)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


