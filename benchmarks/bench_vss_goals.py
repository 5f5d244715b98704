"""VSS goals on the mount emulator (default physics), in lockstep simulated time.

Runs the real VSS against the embedded emulator, both on one lockstep clock (the
figures do not depend on the host's load; at x20 paced time a loaded 2-core host
made the VSS late and the figures meaningless): slew to Vega, 30 s of
sidereal tracking, then the ISS pass of 2024-05-18 19:51 UTC over Poznań
(culminating at 80.1°). Meanwhile an independent ASTCom client streams the
encoders and the mount's own following error at 1 kHz straight from the
emulator. For each goal it prints our figure — the encoders against the
target's observed position computed afresh at every sample time — beside the
mount's own encoder-vs-demand figure (reference minus encoder) from the same
samples, and what the VSS itself reports as the error on target over the same
window (`errors`: its on-target figure must match the independent one).

    python benchmarks/bench_vss_goals.py
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path

import erfa
import numpy as np

from catalogs import load_tle_file, sample_tle_path
from virtualstar.astro import Satellite, UtcTimes, load_site, observe_mount_times, resolve_target
from virtualstar.launcher import embedded_vss
from virtualstar.lockstep import LockstepClock, run_lockstep

START = "2024-05-18T19:40:00Z"
ARCSEC = 180.0 * 3600.0 / np.pi
NAMES = ["axis.az.position", "axis.el.position", "axis.az.error_arcsec", "axis.el.error_arcsec"]


async def run(clock: LockstepClock) -> dict:
    site = load_site()
    chunks: list[tuple[np.ndarray, np.ndarray]] = []
    wall0 = time.perf_counter()
    phases = {}
    async with embedded_vss(clock=clock, site=site) as vss:
        spy = await vss.emulator.connect_in_memory(name="benchmark-spy")
        stream = await spy.stream(NAMES, 1000.0)
        stream.on_packet(lambda p: chunks.append((p.t_us.copy(),
                                                  np.asarray(p.values, float).copy())))
        vs = vss.client()
        op = await vs.request("slew", {"star": "Vega"})
        i = op["info"]
        phases["slew"] = (i["landed_us"], i["landed_us"] + 1_000_000, i["slew_time_s"])
        t0 = i["tracking_from_us"]
        await clock.sleep((t0 + 30_000_000 - clock.now_us) / 1e6)
        phases["sidereal"] = (t0, t0 + 30_000_000, None)
        await vs.request("stop")
        tle = Path(sample_tle_path("stations")).read_text()
        op = await vs.request("track", {"tle": tle, "sat": "ISS", "wait": True})
        i = op["info"]
        phases["satellite"] = (i["tracking_from_us"], min(i["tracking_to_us"], i["pass_end_us"]),
                               i["culmination_el_deg"])
        await clock.sleep(1.0)  # the last samples of the pass have arrived
        reported = {name: (await vs.request("errors", {"from_us": lo, "to_us": hi}))["stats"]
                    for name, (lo, hi, _) in phases.items()}
        await stream.stop()
        await spy.close()
    wall = time.perf_counter() - wall0
    t = np.concatenate([c[0] for c in chunks])
    v = np.concatenate([c[1] for c in chunks])
    return {"site": site, "t": t, "v": v, "phases": phases, "wall": wall, "reported": reported}


def errors(site, target, t, v, lo, hi, step=10):
    """Return (ours, mount's) on-sky errors (arcsec) over [lo, hi), every `step`-th sample."""
    sel = np.flatnonzero((t >= lo) & (t < hi))[::step]
    obs = observe_mount_times(target, t[sel], site)
    az, el = v[sel, 0], v[sel, 1]
    ours = erfa.seps(np.mod(az, 2 * np.pi), el, obs.az_rad, obs.el_rad) * ARCSEC
    mount = np.hypot(v[sel, 2] * np.cos(el), v[sel, 3])
    return ours, mount


def main() -> None:
    clock = LockstepClock(int(UtcTimes.from_iso([START]).to_unix_us()[0]))
    res = run_lockstep(run(clock), clock)
    site, t, v, ph, rep = res["site"], res["t"], res["v"], res["phases"], res["reported"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = next(r for r in load_tle_file(sample_tle_path("stations")) if "ISS" in r.name)
    vega, iss = resolve_target("Vega"), Satellite.from_record(rec)
    rows = []
    lo, hi, slew_s = ph["slew"]
    o, m = errors(site, vega, t, v, lo, hi, step=1)
    rows.append((f"slew to Vega ({slew_s:.1f} s) lands within 1″", "peak ≤ 1″",
                 f"peak {o.max():.3f}″", f"peak {m.max():.3f}″",
                 f"peak {rep['slew']['on_target_peak_arcsec']:.3f}″", o.max() <= 1.0))
    lo, hi, _ = ph["sidereal"]
    o, m = errors(site, vega, t, v, lo, hi)
    rms = lambda x: float(np.sqrt(np.mean(x**2)))  # noqa: E731
    rows.append(("sidereal tracking Vega, 30 s", "RMS ≤ 0.1″", f"RMS {rms(o):.4f}″ "
                 f"(peak {o.max():.3f}″)", f"RMS {rms(m):.4f}″",
                 f"RMS {rep['sidereal']['on_target_rms_arcsec']:.4f}″", rms(o) <= 0.1))
    lo, hi, culm = ph["satellite"]
    o, m = errors(site, iss, t, v, lo, hi, step=20)
    rows.append((f"ISS pass culminating at {culm:.1f}°, {(hi - lo) / 1e6:.0f} s", "RMS ≤ 2″",
                 f"RMS {rms(o):.3f}″ (peak {o.max():.3f}″)", f"RMS {rms(m):.3f}″ "
                 f"(peak {m.max():.3f}″)", f"RMS {rep['satellite']['on_target_rms_arcsec']:.3f}″ "
                 f"(peak {rep['satellite']['on_target_peak_arcsec']:.3f}″)", rms(o) <= 2.0))
    print(f"VSS goals on the mount emulator, default physics, lockstep simulated time "
          f"({res['wall']:.0f} s wall, {len(t)} encoder samples at 1 kHz)")
    print(f"{'goal':46} {'target':11} {'ours: encoders vs target':34} "
          f"{'reference: mount encoder vs demand':34} {'the VSS reports on target':32} met")
    for goal, target, ours, ref, vss, ok in rows:
        print(f"{goal:46} {target:11} {ours:34} {ref:34} {vss:32} {'yes' if ok else 'NO'}")


if __name__ == "__main__":
    main()
