"""`vs pointing-run`: measure a TPOINT pointing run through the VSS and the guide camera.

Stars are planned with `pointing_model`'s own planner (spread evenly over the sky
visible from the server's site at the server's mount time); each is measured with
the API command `pointing_sample`. A TPOINT record pairs the *sky place on the
optical axis* (the star's observed place minus the camera offset) with the raw
encoder reading. That pair is exact whatever the offset: observed − raw is the
mount's error at the observed place, which is what TPOINT fits. (Writing the star's
place with "encoders + offset" instead would evaluate the error at the wrong place
by the offset — a second-order error of ~0.1–0.5″ with offsets of a few arcminutes.)
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from virtualstar.cli.status import JsonOpt, ServerOpt, api_password, fail, print_json
from virtualstar.vss_client import ServerUnavailable, VssClient, VssRequestError, default_server_url

__all__ = ["RunResult", "measure_stars", "plan_for_server", "pointing_run", "samples_to_run"]

MIN_SAMPLES = 3  # fewer cannot even fit IA and IE with a residual


@dataclass
class RunResult:
    """Samples measured (API `pointing_sample` answers) and stars that could not be."""

    samples: list[dict[str, Any]] = field(default_factory=list)
    skipped: list[dict[str, str]] = field(default_factory=list)
    site: dict[str, Any] = field(default_factory=dict)

    @property
    def raw_sky_rms_arcsec(self) -> float:
        """RMS of the camera offsets (star − optical axis) on the sky, arcsec."""
        tot = [s["offset_arcsec"]["total"] for s in self.samples]
        return math.sqrt(math.fsum(x * x for x in tot) / len(tot)) if tot else float("nan")


def plan_for_server(status: dict[str, Any], n_stars: int, *, at_utc: str | None,
                    min_el_deg: float) -> list[Any]:
    """Plan `n_stars` for the site and mount time of a server's status, sorted by azimuth.

    Raises ValueError (bad time, too few stars) or KeyError (a status without site).
    """
    from pointing_model.cli_sky import plan_stars
    from virtualstar.astro import Site

    site = Site.from_dict(status["site"])
    at = at_utc or status.get("mount_time_utc")
    stars = plan_stars(n_stars, site, at_utc=at, min_el_deg=min_el_deg,
                       exclude=_server_zones(status, site))
    return sorted(stars, key=lambda s: s.az_deg)  # short slews: go round the horizon once


def _server_zones(status: dict[str, Any], site: Any):
    """Return an exclude(az_deg, el_deg, times) for the server's zones (horizon, Sun, Moon)."""
    import numpy as np

    from virtualstar.astro import AvoidanceZones, zone_mask

    doc = status.get("safety")
    if not doc:
        return None
    zones = AvoidanceZones.from_dict(doc)

    def exclude(az_deg, el_deg, times):
        t_us = np.full(len(az_deg), int(times.to_unix_us()[0]), np.int64)
        return zone_mask(np.radians(az_deg), np.radians(el_deg), t_us, zones, site)

    return exclude


async def measure_stars(client: VssClient, stars: list[Any], *, settle_s: float = 2.0,
                        on_sample: Callable[[Any, dict[str, Any] | None], None] | None = None,
                        ) -> RunResult:
    """Measure each planned star with `pointing_sample`; unreachable ones are skipped.

    Raises VssRequestError for anything but an unreachable star (a fault, no camera).
    """
    result = RunResult()
    for star in stars:
        try:
            sample = await client.request("pointing_sample", {
                "ra_deg": star.ra_deg, "dec_deg": star.dec_deg, "settle_s": settle_s})
        except VssRequestError as exc:
            if exc.code not in ("unreachable", "exclusion_zone"):
                raise
            result.skipped.append({"star": star.name, "error": exc.message})
            sample = None
        else:
            sample["star_name"] = star.name
            result.samples.append(sample)
        if on_sample is not None:
            on_sample(star, sample)
    return result


def samples_to_run(result: RunResult, caption: str) -> Any:
    """Return a `PointingRun`: observed = sky place on the optical axis, raw = encoders."""
    import numpy as np

    from pointing_model import PointingRun, RunParameters

    s = result.samples
    site = result.site
    first = s[0]["utc"] if s else "1970-01-01"
    y, m, d = (int(x) for x in first[:10].split("-"))
    params = RunParameters(latitude_deg=float(site.get("lat_deg", 0.0)), date=(y, m, d),
                           temperature_c=site.get("temperature_c"),
                           pressure_hpa=site.get("pressure_hpa"), height_m=site.get("height_m"),
                           humidity=site.get("humidity"))
    comments = tuple(
        f"{x['star_name']} {x['utc']} star {x['star']['az_deg']:.6f} {x['star']['el_deg']:.6f} "
        f"offset {x['offset_arcsec']['dx']:+.2f} {x['offset_arcsec']['dy']:+.2f}" for x in s)
    return PointingRun(np.array([x["axis"]["az_deg"] for x in s]),
                       np.array([x["axis"]["el_deg"] for x in s]),
                       np.array([x["encoder"]["az_deg"] for x in s]),
                       np.array([x["encoder"]["el_deg"] for x in s]),
                       params, caption=caption, comments=comments)


def pointing_run(
    stars: Annotated[int, typer.Option(
        "--stars", help="How many stars to measure (spread evenly over the visible sky).",
        min=1, max=1000)] = 40,
    output: Annotated[Path, typer.Option(
        "-o", "--output", help="TPOINT data file to write (fit it with `pointing-model fit`).")
    ] = Path("run.dat"),
    at: Annotated[str | None, typer.Option(
        "--at", help="UTC (ISO 8601) for which to plan the stars; default: the server's "
                     "mount time.")] = None,
    min_el: Annotated[float, typer.Option(
        "--min-el", help="Lowest elevation of a planned star, degrees.", min=5.0, max=80.0)] = 20.0,
    settle: Annotated[float, typer.Option(
        "--settle", help="Mount seconds to hold before each camera measurement.", min=0.0)] = 2.0,
    server: ServerOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """Slew to N stars, measure each with the guide camera, write a TPOINT data file.

    Records pair the sky place on the optical axis (observed) with the encoders (raw). Fit them with `pointing-model fit FILE -o model.json`, then `vs model load model.json`. A model already loaded does not change the raw readings.
    """  # noqa: E501 (one line: typer's help keeps the docstring's line breaks)
    url = server or default_server_url()
    if output.exists() and output.is_dir():
        raise fail(f"--output {output} is a directory; expected a file name such as run.dat")
    if not output.parent.exists():
        raise fail(f"--output {output}: folder {output.parent} does not exist")
    console = Console(stderr=True)
    try:
        result = asyncio.run(_run(url, stars, at, min_el, settle, console, quiet=as_json))
    except ServerUnavailable as exc:
        raise fail(str(exc), 2) from None
    except VssRequestError as exc:
        raise fail(f"the server refused a pointing sample: {exc.message} [{exc.code}]", 1) from None
    except ValueError as exc:
        raise fail(f"cannot plan the stars: {exc}") from None
    if len(result.samples) < MIN_SAMPLES:
        raise fail(f"only {len(result.samples)} star(s) could be measured (at least "
                   f"{MIN_SAMPLES} needed); skipped: "
                   + "; ".join(f"{s['star']}: {s['error']}" for s in result.skipped), 1)
    from pointing_model import write_tpoint

    run = samples_to_run(result, f"VirtualStar pointing run, {result.samples[0]['utc']} UTC, "
                                 f"{len(result.samples)} stars via {url}")
    with output.open("w", encoding="utf-8") as f:
        write_tpoint(run, f)
    summary = {"file": str(output), "n_obs": len(result.samples),
               "n_skipped": len(result.skipped), "skipped": result.skipped,
               "raw_sky_rms_arcsec": result.raw_sky_rms_arcsec,
               "pointing_model": result.samples[0].get("pointing_model"),
               "samples": result.samples}
    if as_json:
        print_json(summary)
    else:
        Console().print(_summary_table(summary))


async def _run(url: str, n: int, at: str | None, min_el: float, settle: float,
               console: Console, *, quiet: bool) -> RunResult:
    async with await VssClient.connect(url, password=api_password()) as client:
        status = await client.request("status")
        if not status.get("connected"):
            raise VssRequestError("mount_offline", f"the server has no mount connected "
                                  f"({status.get('mount_error') or 'connecting'})")
        try:
            planned = plan_for_server(status, n, at_utc=at, min_el_deg=min_el)
        except KeyError:
            raise VssRequestError("bad_request", "the server's status has no 'site': it is "
                                  "too old for pointing runs") from None
        columns = (TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                   TextColumn("{task.fields[last]}"), TimeElapsedColumn())
        with Progress(*columns, console=console, disable=quiet) as progress:
            task = progress.add_task("pointing run", total=len(planned), last="")

            def on_sample(star: Any, sample: dict[str, Any] | None) -> None:
                last = (f"{star.name}: offset {sample['offset_arcsec']['total']:.1f}″"
                        if sample else f"{star.name}: skipped")
                progress.update(task, advance=1, last=last)

            result = await measure_stars(client, planned, settle_s=settle, on_sample=on_sample)
        result.site = status["site"]
        return result


def _summary_table(summary: dict[str, Any]) -> Table:
    t = Table(title="pointing run", show_header=False, title_justify="left")
    t.add_column("what", style="bold")
    t.add_column("value")
    t.add_row("file", summary["file"])
    t.add_row("stars measured", str(summary["n_obs"]))
    t.add_row("stars skipped", ", ".join(s["star"] for s in summary["skipped"]) or "none")
    t.add_row("camera offset RMS", f"{summary['raw_sky_rms_arcsec']:.2f}″ (star − optical axis, "
              f"model: {summary['pointing_model'] or 'none'})")
    worst = max(summary["samples"], key=lambda s: s["offset_arcsec"]["total"])
    t.add_row("largest offset", f"{worst['offset_arcsec']['total']:.2f}″ ({worst['star_name']})")
    t.add_row("next", f"pointing-model fit {summary['file']} --auto -o model.json; "
              "vs model load model.json")
    return t
