"""The VirtualStar demo: one process, simulated time, the embedded emulator, the real VSS.

`run_demo()` places the emulator's clock a little before a high ISS pass over
the site (found with the pass predictor from the bundled TLE), starts the
VirtualStar Server on it, and as an API client: slews to a bright star, tracks
it sidereally, then tracks the ISS through the whole pass. It returns the
per-phase figures (slew time, tracking error RMS and peak) and writes a PNG of
the tracking error over time.
"""

from __future__ import annotations

import asyncio
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

    speed: float = 20.0
    sidereal_s: float = 30.0
    min_culmination_deg: float = 60.0
    before_pass_s: float = 210.0  # clock placed this long before the pass rises
    out_dir: Path = Path("demo-output")
    site: Site | None = None
    tle_set: str = "stations"
    satellite: str = "ISS"


@dataclass
class DemoPhase:
    """One phase: tracking error (arcsec) over [from_us, to_us]; slew time if it is a slew."""

    name: str
    target: str
    rms_arcsec: float
    peak_arcsec: float
    from_us: int
    to_us: int
    slew_time_s: float | None = None

    def as_dict(self) -> dict[str, Any]:
        return {"name": self.name, "target": self.target, "rms_arcsec": self.rms_arcsec,
                "peak_arcsec": self.peak_arcsec, "duration_s": (self.to_us - self.from_us) / 1e6,
                "slew_time_s": self.slew_time_s}


@dataclass
class DemoResult:
    phases: list[DemoPhase] = field(default_factory=list)
    plot: str | None = None
    wall_s: float = 0.0
    pass_info: dict[str, Any] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        return {"phases": [p.as_dict() for p in self.phases], "plot": self.plot,
                "wall_s": self.wall_s, "pass": self.pass_info}


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


async def run_demo(config: DemoConfig = DemoConfig(),
                   say: Callable[[str], None] = lambda text: None) -> DemoResult:
    """Run the whole demo on this event loop; return its phases and plot path."""
    from catalogs import load_tle_file, sample_tle_path, select_satellite
    from virtualstar.launcher import start_emulator
    from virtualstar.server import build_server
    from virtualstar.vss_client import VssClient

    wall0 = time.perf_counter()
    site = config.site or load_site()
    tle_path = sample_tle_path(config.tle_set)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        records = load_tle_file(tle_path)
    records = [r for r in records if config.satellite.lower() in r.name.lower()] or records
    sat = Satellite.from_record(select_satellite(records, records[0].name))
    rise_us, set_us, culm = find_demo_pass(site, sat, config.min_culmination_deg)
    start_us = rise_us - int(config.before_pass_s * 1e6)
    star = pick_star(site, start_us + 30_000_000)
    result = DemoResult(pass_info={"satellite": sat.name, "rise_utc": _iso(rise_us),
                                   "set_utc": _iso(set_us), "culmination_deg": culm})
    say(f"simulated clock {_iso(start_us)} at x{config.speed:g}, site {site.name}; "
        f"{sat.name} rises {_iso(rise_us)}, culminates at {culm:.1f}°")
    emu = await start_emulator(speed=config.speed, start_us=start_us)
    server = build_server(mount_url=emu.url, site=site, speed=config.speed)
    try:
        url = await server.start("ws://127.0.0.1:0")
        async with await VssClient.connect(url, silence_s=30.0) as vs:
            await _wait_mount(vs)
            say(f"slewing to {star}")
            op = await vs.request("slew", {"star": star})
            info = op["info"]
            result.phases.append(DemoPhase(
                f"slew to {star} (landing)", star, info["landing_rms_arcsec"],
                info["landing_peak_arcsec"], info["landed_us"],
                info["landed_us"] + int(server.telescope.config.settle_s * 1e6),
                info["slew_time_s"]))
            say(f"landed after {info['slew_time_s']:.1f} s; sidereal tracking for "
                f"{config.sidereal_s:g} s")
            from_us = info["tracking_from_us"]
            await _wait_mount_time(vs, from_us + int(config.sidereal_s * 1e6), config.speed)
            await vs.request("stop")
            to_us = from_us + int(config.sidereal_s * 1e6)
            s = (await vs.request("errors", {"from_us": from_us, "to_us": to_us}))["stats"]
            result.phases.append(DemoPhase(f"sidereal tracking {star}", star, s["rms_arcsec"],
                                           s["peak_arcsec"], from_us, to_us))
            say(f"waiting for {sat.name} (pass {_iso(rise_us)} .. {_iso(set_us)})")
            tle_text = Path(tle_path).read_text(encoding="utf-8")
            await vs.request("track", {"tle": tle_text, "sat": sat.name})
            say(f"tracking {sat.name} through the pass")
            op = await vs.request("wait", {})
            info = op["info"]
            result.phases.append(DemoPhase(
                f"satellite pass {sat.name}", sat.name, info["tracking_rms_arcsec"],
                info["tracking_peak_arcsec"], info["tracking_from_us"], info["tracking_to_us"]))
            result.pass_info.update({k: info.get(k) for k in (
                "keyhole", "keyhole_max_error_arcsec", "max_az_rate_deg_s")})
            series = (await vs.request("errors", {"series": True, "max_points": 4000,
                                                  "from_us": start_us}))["series"]
        result.plot = str(_plot(series, result.phases, config.out_dir))
    finally:
        await server.close()
        await emu.stop()
    result.wall_s = time.perf_counter() - wall0
    return result


async def _wait_mount(vs) -> None:
    for _ in range(200):
        if (await vs.request("status")).get("connected"):
            return
        await asyncio.sleep(0.05)
    raise RuntimeError("the VSS did not connect to the embedded emulator")


async def _wait_mount_time(vs, t_us: int, speed: float) -> None:
    while True:
        st = await vs.request("status")
        left = (t_us - st["mount_time_us"]) / 1e6
        if left <= 0:
            return
        await asyncio.sleep(min(0.5, max(0.01, left / speed)))


def _plot(series: dict[str, list], phases: list[DemoPhase], out_dir: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / "tracking-error.png"
    t = np.asarray(series["t_us"], dtype=np.int64)
    t0 = int(t[0]) if t.size else 0
    fig, ax = plt.subplots(figsize=(10, 4.5))
    for p in phases:
        if "landing" in p.name:
            continue
        ax.axvspan((p.from_us - t0) / 1e6, (p.to_us - t0) / 1e6, alpha=0.12,
                   color="tab:green" if "sidereal" in p.name else "tab:blue")
        ax.text((p.from_us - t0) / 1e6, 0.95, p.name, transform=ax.get_xaxis_transform(),
                fontsize=8, va="top")
    ax.semilogy((t - t0) / 1e6, np.maximum(series["peak_arcsec"], 1e-4), lw=0.6,
                color="tab:red", label="peak per 0.1 s")
    ax.semilogy((t - t0) / 1e6, np.maximum(series["rms_arcsec"], 1e-4), lw=0.8,
                color="tab:blue", label="RMS per 0.1 s")
    ax.set_xlabel(f"mount time since {_iso(t0)} [s]")
    ax.set_ylabel("on-sky following error [arcsec]")
    ax.set_title("VirtualStar demo: tracking error (slews, sidereal, satellite pass)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _iso(t_us: int) -> str:
    return UtcTimes.from_unix_us(int(t_us)).iso(0)[0]
