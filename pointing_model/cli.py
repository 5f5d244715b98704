"""The `pointing-model` command line: fit, plan, simulate, apply (thin over the library)."""

from __future__ import annotations

import csv
import json
import math
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from .constants import GEOMETRIC_TERMS
from .exceptions import PointingModelError

if TYPE_CHECKING:
    from .fitting import FitResult
    from .model import PointingModel

# The fit (numpy, scipy) and the astronomy are imported when a command runs: --help stays
# fast (tests/test_import_rules.py).

app = typer.Typer(
    name="pointing-model",
    help="Fit, inspect and apply a TPOINT-style pointing model of an alt-az mount.",
    no_args_is_help=True,
    add_completion=False,
)

EXIT_DATA = 1  # bad file contents, fit impossible
EXIT_USAGE = 2  # bad arguments (Typer uses 2 for its own usage errors too)


def main() -> None:
    """Run the `pointing-model` command line."""
    app()


def _fail(message: str, code: int = EXIT_DATA) -> typer.Exit:
    typer.echo(f"error: {message}", err=True)
    return typer.Exit(code)


@contextmanager
def _errors_to_exit() -> Iterator[None]:
    try:
        yield
    except PointingModelError as exc:
        raise _fail(str(exc)) from None
    except OSError as exc:  # a file named on the command line that cannot be read: an argument
        raise _fail(f"{exc.filename or ''}: {exc.strerror or exc}".lstrip(": "),
                    EXIT_USAGE) from None
    except ValueError as exc:
        raise _fail(str(exc), EXIT_USAGE) from None


# -- fit ----------------------------------------------------------------------------------
@app.command()
def fit(
    data: Annotated[Path, typer.Argument(help="Pointing run: TPOINT format (.dat, any suffix) "
                                         "or CSV (.csv).")],
    terms: Annotated[str | None, typer.Option(
        "--terms", help="Comma-separated TPOINT terms, e.g. IA,IE,CA,AN,AW,TX or harmonics "
        f"like HASA2. Default: {','.join(GEOMETRIC_TERMS)}.")] = None,
    auto: Annotated[bool, typer.Option(
        "--auto", help="Choose terms by forward selection from IA,IE (partial F-test, "
        "Bonferroni 1%).")] = False,
    reject_sigma: Annotated[float | None, typer.Option(
        "--reject-sigma", help="Drop observations, worst first, while one lies more than "
        "K × sky RMS from the fit.", min=0.5)] = None,
    output: Annotated[Path | None, typer.Option(
        "-o", "--output", help="Write the fitted model here: TPOINT's model layout when the "
        "name ends in .mod, else our JSON.")] = None,
    plot: Annotated[Path | None, typer.Option(
        "--plot", help="Write residual plots (PNG) here.")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print the fit as JSON.")] = False,
    site: Annotated[str | None, typer.Option(
        "--site", help="LAT,LON,HEIGHT_M (deg, deg east, m); only for CSV rows given as "
        "RA/Dec.")] = None,
    site_file: Annotated[str | None, typer.Option(
        "--site-file", help="Site TOML (default $VIRTUALSTAR_SITE or the packaged site); "
        "only for CSV rows given as RA/Dec.")] = None,
    substitute: Annotated[list[str] | None, typer.Option(
        "--substitute", help="OLD=NEW: fit TPOINT term OLD (named in --terms) as our term NEW "
        "(e.g. TX10=TX, see docs/pointing-model.md); a .mod output names it OLD again. "
        "Repeatable.")] = None,
) -> None:
    """Fit pointing terms to a pointing run and report values, σ, RMS, PSD and diagnostics."""
    import dataclasses

    from .fitting import fit_run, select_terms
    from .run_files import load_run
    from .terms import parse_term_list
    from .tpoint_model_file import save_tpoint_model

    if auto and terms:
        raise _fail("give either --terms or --auto, not both", EXIT_USAGE)
    mapping = _parse_substitutions(substitute or [])
    if mapping and auto:
        raise _fail("--substitute renames terms of --terms; --auto chooses among our own",
                    EXIT_USAGE)
    asked = (terms or ",".join(GEOMETRIC_TERMS)).replace(" ", ",").split(",")
    try:
        names = None if auto else parse_term_list(
            [mapping.get(t.strip().upper(), t) for t in asked])
    except ValueError as exc:  # includes UnknownTermError
        raise _fail(f"--terms: {exc}", EXIT_USAGE) from None
    unused = sorted(set(mapping) - {t.strip().upper() for t in asked})
    if unused:
        raise _fail(f"--substitute {', '.join(unused)}: not among --terms", EXIT_USAGE)
    substituted = {parse_term_list([new])[0]: old for old, new in mapping.items()}
    with _errors_to_exit():
        converter = _lazy_radec_converter(site, site_file)
        run = load_run(data, radec_to_altaz=converter)
        result = (select_terms(run, reject_sigma=reject_sigma) if names is None
                  else fit_run(run, names, reject_sigma=reject_sigma))
        model = result.model
        if substituted:  # the model file says which TPOINT term each stands for
            model = dataclasses.replace(model, fit_info={**model.fit_info,
                                                         "substituted": substituted})
        if output is not None and output.suffix.lower() == ".mod":
            save_tpoint_model(model, output, caption=run.caption)
        elif output is not None:
            model.save(output)
        if plot is not None:
            from .plotting import plot_residuals

            plot_residuals(run, result, plot)
    if as_json:
        doc = result.to_json_dict()
        if substituted:
            doc["substituted"] = substituted
        typer.echo(json.dumps(doc, indent=2))
    else:
        typer.echo(_format_fit(result))
        for ours, theirs in substituted.items():
            typer.echo(f"{theirs} fitted as {ours} (--substitute {theirs}={ours})")


def _format_fit(result: FitResult) -> str:
    masked = f", {result.n_masked} masked with ';' in the file" if result.n_masked else ""
    lines = [f"{result.source}: {result.n_obs} observations used, {result.n_rejected} rejected"
             f"{masked}",
             f"{'term':>10} {'value″':>11} {'σ″':>8}"]
    for name, v, s in zip(result.terms, result.values_arcsec, result.sigmas_arcsec, strict=True):
        lines.append(f"{name:>10} {v:11.2f} {s:8.2f}")
    lines += [
        f"sky RMS {result.sky_rms_arcsec:.2f}″   PSD {result.psd_arcsec:.2f}″   "
        f"leave-one-out RMS {result.loo_rms_arcsec:.2f}″   raw sky RMS "
        f"{result.raw_sky_rms_arcsec:.2f}″",
        f"condition number {result.condition_number:.3g}   "
        "(σ as TPOINT: sky RMS × √diag (XᵀX)⁻¹)",
    ]
    for a, b, r in result.high_correlations:
        lines.append(f"correlation {a}-{b} = {r:+.3f}")
    if result.n_rejected:
        lines.append("rejected lines: " + ", ".join(
            str(v) for v in result.to_json_dict()["rejected_lines"]))
    for step in result.selection:
        verdict = "added" if step.accepted else "stopped"
        lines.append(f"auto: {step.term:>8} F={step.f_statistic:10.2f} p={step.p_value:.2e} "
                     f"among {step.candidates_tried} → {verdict}")
    return "\n".join(lines)


def _lazy_radec_converter(site: str | None, site_file: str | None) -> Callable[..., Any]:
    def convert(utcs: Any, ra_deg: Any, dec_deg: Any) -> Any:
        from .cli_sky import make_site, radec_to_observed_altaz

        return radec_to_observed_altaz(list(utcs), ra_deg, dec_deg, make_site(site, site_file))

    return convert


# -- plan ---------------------------------------------------------------------------------
@app.command()
def plan(
    stars: Annotated[int, typer.Option("--stars", help="Number of stars to pick.", min=1)],
    at: Annotated[str | None, typer.Option(
        "--at", help="UTC of the run, ISO 8601 (e.g. 2026-11-22T03:00:00Z). Default: now.")
    ] = None,
    min_el_deg: Annotated[float, typer.Option("--min-el", help="Lowest elevation, deg.")] = 20.0,
    max_el_deg: Annotated[float, typer.Option("--max-el", help="Highest elevation, deg.")] = 85.0,
    max_vmag: Annotated[float | None, typer.Option(
        "--max-vmag", help="Faintest V magnitude to use.")] = None,
    site: Annotated[str | None, typer.Option(
        "--site", help="LAT,LON,HEIGHT_M (deg, deg east, m), overriding the site file.")] = None,
    site_file: Annotated[str | None, typer.Option(
        "--site-file", help="Site TOML (default $VIRTUALSTAR_SITE or the packaged site).")
    ] = None,
    output: Annotated[Path | None, typer.Option(
        "-o", "--output", help="Also write the plan as CSV (name, utc, ra/dec, obs az/el).")
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print the plan as JSON.")] = False,
) -> None:
    """Pick catalogue stars spread evenly over the sky visible at a time, for a pointing run."""
    with _errors_to_exit():
        from .cli_sky import make_site, plan_stars

        chosen = plan_stars(stars, make_site(site, site_file), at_utc=at, min_el_deg=min_el_deg,
                            max_el_deg=max_el_deg, max_vmag=max_vmag)
        if output is not None:
            _write_plan_csv(chosen, output)
    if as_json:
        typer.echo(json.dumps([star.__dict__ for star in chosen], indent=2))
        return
    typer.echo(f"{'#':>3} {'star':<16} {'HIP':>6} {'V':>5} {'RA°':>9} {'Dec°':>9} "
               f"{'az°':>8} {'el°':>7}   UTC {chosen[0].utc if chosen else ''}")
    for i, s in enumerate(chosen, start=1):
        vmag = f"{s.vmag:5.2f}" if s.vmag is not None else "    -"
        typer.echo(f"{i:3d} {s.name:<16.16} {s.hip or '':>6} {vmag} {s.ra_deg:9.4f} "
                   f"{s.dec_deg:9.4f} {s.az_deg:8.3f} {s.el_deg:7.3f}")


def _write_plan_csv(chosen: list[Any], path: Path) -> None:
    with open(path, "w", encoding="utf-8", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["name", "hip", "vmag", "utc", "ra_deg", "dec_deg", "obs_az_deg",
                         "obs_el_deg"])
        for s in chosen:
            writer.writerow([s.name, s.hip or "", "" if s.vmag is None else s.vmag, s.utc,
                             f"{s.ra_deg:.8f}", f"{s.dec_deg:.8f}", f"{s.az_deg:.7f}",
                             f"{s.el_deg:.7f}"])


# -- simulate -----------------------------------------------------------------------------
@app.command()
def simulate(
    model: Annotated[str, typer.Option(
        "--model", help="Model JSON file, or inline values like 'IA=-30,IE=20,CA=12'.")],
    stars: Annotated[int, typer.Option("--stars", help="Number of observations.", min=1)],
    noise: Annotated[float, typer.Option(
        "--noise", help="Gaussian noise per sky axis, arcsec.", min=0.0)],
    output: Annotated[Path | None, typer.Option(
        "-o", "--output", help="Write the TPOINT file here (default: standard output).")] = None,
    seed: Annotated[int | None, typer.Option("--seed", help="Random seed (repeatable runs).")] = None,
    min_el_deg: Annotated[float, typer.Option("--min-el", help="Lowest elevation, deg.")] = 20.0,
    max_el_deg: Annotated[float, typer.Option("--max-el", help="Highest elevation, deg.")] = 85.0,
    latitude_deg: Annotated[float | None, typer.Option(
        "--latitude-deg", help="Site latitude written to the run-parameters line; default: "
        "the site file's ($VIRTUALSTAR_SITE or the packaged site).")] = None,
    site_file: Annotated[str | None, typer.Option(
        "--site-file", help="Site TOML giving the latitude (default $VIRTUALSTAR_SITE or the "
        "packaged site).")] = None,
) -> None:
    """Write a synthetic pointing run (TPOINT format) drawn from a model plus noise."""
    import numpy as np

    from .simulate import simulate_run
    from .tpoint_format import write_tpoint

    with _errors_to_exit():
        if latitude_deg is None:
            from .cli_sky import make_site

            latitude_deg = make_site(None, site_file).lat_deg
        pm = _model_argument(model)
        rng = np.random.default_rng(seed)
        run = simulate_run(pm, stars, noise, rng=rng, min_el_deg=min_el_deg,
                           max_el_deg=max_el_deg, latitude_deg=latitude_deg)
        if output is None:
            write_tpoint(run, sys.stdout)
        else:
            with open(output, "w", encoding="utf-8") as f:
                write_tpoint(run, f)
    if output is not None:
        typer.echo(f"wrote {stars} observations to {output}", err=True)


def _model_argument(text: str) -> PointingModel:
    from .model import load_model, model_from_values

    if "=" in text and not Path(text).exists():
        values = []
        for item in text.replace(" ", ",").split(","):
            if not item:
                continue
            name, sep, value = item.partition("=")
            try:
                values.append((name, float(value)))
            except ValueError:
                raise ValueError(f"--model: {item!r} is not NAME=ARCSEC (e.g. IA=-30)") from None
            if not sep:
                raise ValueError(f"--model: {item!r} is not NAME=ARCSEC (e.g. IA=-30)")
        return model_from_values(values)
    return load_model(text)


# -- apply --------------------------------------------------------------------------------
@app.command()
def apply(
    model: Annotated[Path, typer.Argument(
        help="Model file: JSON written by `fit -o`, or a TPOINT model (.mod, OUTMOD layout).")],
    altaz: Annotated[str, typer.Option(
        "--altaz", help="Observed position 'AZ EL' in degrees (azimuth N through E).")],
    inverse: Annotated[bool, typer.Option(
        "--inverse", help="Treat --altaz as encoder readings and print the observed "
        "position.")] = False,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
    substitute: Annotated[list[str] | None, typer.Option(
        "--substitute", help="OLD=NEW: read TPOINT term OLD as our term NEW (e.g. TX10=TX, "
        "see docs/pointing-model.md); repeatable.")] = None,
) -> None:
    """Print the encoder demand for an observed position (or the reverse with --inverse)."""
    from .model import load_model

    az, el = _parse_altaz(altaz)
    mapping = _parse_substitutions(substitute or [])
    with _errors_to_exit():
        pm = load_model(model, substitute=mapping)
        if inverse:
            out_az, out_el = pm.encoder_to_observed(az, el)
        else:
            out_az, out_el = pm.observed_to_encoder(az, el)
    out_az, out_el = float(out_az), float(out_el)
    key = "observed" if inverse else "encoder"
    if as_json:
        typer.echo(json.dumps({f"{key}_az_deg": out_az, f"{key}_el_deg": out_el,
                               "input_az_deg": az, "input_el_deg": el}))
    else:
        typer.echo(f"{key} az {out_az:.7f} el {out_el:.7f} deg")


def _parse_substitutions(items: list[str]) -> dict[str, str]:
    mapping = {}
    for item in items:
        old, sep, new = item.partition("=")
        if not (sep and old.strip() and new.strip()):
            raise _fail(f"--substitute {item!r}: expected OLD=NEW, e.g. --substitute TX10=TX",
                        EXIT_USAGE)
        mapping[old.strip().upper()] = new.strip().upper()
    return mapping


def _parse_altaz(text: str) -> tuple[float, float]:
    parts = text.replace(",", " ").split()
    try:
        az, el = (float(p) for p in parts)
    except ValueError:
        raise _fail(f"--altaz {text!r}: expected two numbers 'AZ EL' in degrees, "
                    "e.g. --altaz '120.5 45'", EXIT_USAGE) from None
    if not (math.isfinite(az) and -90.0 < el < 90.0):
        raise _fail(f"--altaz {text!r}: elevation must lie strictly between -90 and 90 degrees",
                    EXIT_USAGE)
    return az, el
