"""`vs status`: where the mount points, what it does, and how well it tracks.

Also holds what every VSS client command shares: the --server and --json
options and `ask()`, which sends one command and turns failures into clear
errors on stderr with exit code 1 (the server refused) or 2 (no server).
"""

from __future__ import annotations

import json
import math
from typing import Annotated, Any

import typer
from rich.console import Console
from rich.table import Table

from virtualstar.vss_client import SERVER_ENV_VAR, default_server_url

__all__ = ["JsonOpt", "ServerOpt", "api_password", "ask", "fail", "render_status", "set_api_password",
           "status"]

_api_password: str | None = None  # from `vs --password` / $VS_PASSWORD (the root command)


def set_api_password(password: str | None) -> None:
    """Remember the VSS password given to the root `vs` command for every client command."""
    global _api_password
    _api_password = password or None


def api_password() -> str | None:
    return _api_password

ServerOpt = Annotated[str | None, typer.Option(
    "--server", help=f"VirtualStar Server URL (default ${SERVER_ENV_VAR} or "
                     f"{default_server_url()}).", show_default=False)]
JsonOpt = Annotated[bool, typer.Option("--json", help="Print JSON for scripts instead of tables.")]


def fail(message: str, code: int = 2, *, as_json: bool = False) -> typer.Exit:
    """Print `error: message` to stderr and return the Exit to raise.

    With `as_json` the error also goes to stdout as `{"error": {"code", "message"}}`
    (code `bad_input` for exit code 2, else `refused`), so a script reads one stream.
    """
    if as_json:
        print_json({"error": {"code": "bad_input" if code == 2 else "refused",
                              "message": message}})
    typer.echo(f"error: {message}", err=True)
    return typer.Exit(code)


def ask(server: str | None, cmd: str, params: dict[str, Any] | None = None, *,
        progress: bool = False, quiet: bool = False, on_event=None) -> Any:
    """Send one command to the server and return its result, or exit with a clear error.

    progress=True shows the server's operation events under a spinner (humans only);
    `on_event(kind, data)` sees every event instead.
    With `quiet` (the command's --json), a failure also prints a JSON error object on
    stdout (`{"error": {"code", "message"}}`), so a script parses the same stream either way.
    """
    from virtualstar.display import safe_text
    from virtualstar.vss_client import ServerUnavailable, VssRequestError, call_server

    url = server or default_server_url()
    console = Console(stderr=True)
    try:
        if on_event is None and progress and not quiet and console.is_terminal:
            with console.status(f"{cmd}...") as spinner:
                def on_event(kind: str, data: dict[str, Any]) -> None:
                    if kind == "operation":
                        info = data.get("info", {})
                        left = info.get("seconds_left")
                        spinner.update(f"{data.get('kind')} {shown(data.get('target'))}: "
                                       f"{data.get('phase')}"
                                       + (f" ({left:.0f} s mount time left)" if left else ""))
                    elif kind == "fault":
                        console.print(f"[red]mount fault: {data.get('faults')}")

                return call_server(url, cmd, params, on_event=on_event,
                                   password=api_password())
        return call_server(url, cmd, params, on_event=on_event, password=api_password())
    except VssRequestError as exc:
        if quiet:
            print_json({"error": {"code": exc.code, "message": exc.message}})
        raise fail(f"the server refused {cmd}: {safe_text(exc.message)} [{exc.code}]",
                   1) from None
    except ServerUnavailable as exc:
        if quiet:
            print_json({"error": {"code": "server_unavailable", "message": str(exc)}})
        raise fail(str(exc), 2) from None


def shown(text: Any) -> str:
    """Return outside text (a target or TLE name, a server's message) for a rich cell or
    line: control and bidirectional characters escaped, rich markup made inert."""
    from rich.markup import escape

    from virtualstar.display import safe_text

    return escape(safe_text(text))


def print_json(doc: Any) -> None:
    typer.echo(json.dumps(doc, indent=2, allow_nan=False, default=str))


def _f(value: Any, fmt: str = ".4f", unit: str = "") -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    return f"{value:{fmt}}{unit}"


def _hms(ra_deg: float) -> str:
    h = ra_deg / 15.0
    hh, rem = divmod(h * 3600.0, 3600.0)
    mm, ss = divmod(rem, 60.0)
    return f"{int(hh):02d}h{int(mm):02d}m{ss:05.2f}s"


def _dms(dec_deg: float) -> str:
    sign = "-" if dec_deg < 0 else "+"
    d, rem = divmod(abs(dec_deg) * 3600.0, 3600.0)
    m, s = divmod(rem, 60.0)
    return f"{sign}{int(d):02d}d{int(m):02d}m{s:04.1f}s"


def render_status(st: dict[str, Any]) -> Table:
    """Return a rich table of a status result."""
    t = Table(title="VirtualStar", show_header=False, title_justify="left")
    t.add_column("what", style="bold")
    t.add_column("value")
    if not st.get("connected"):
        t.add_row("mount", f"[red]not connected[/] ({st.get('url')}: {st.get('mount_error')})")
        return t
    t.add_row("mount", f"{st['mount_state']}  ({st['url']}, {st['mode']}, {_time_mode(st)})")
    t.add_row("mount time", st["mount_time_utc"])
    enc, obs, rd = st["encoder"], st["observed"], st["radec"]
    t.add_row("encoder az / el", f"{enc['az_deg']:.5f}° / {enc['el_deg']:.5f}°")
    t.add_row("observed az / el", f"{obs['az_deg']:.5f}° / {obs['el_deg']:.5f}°")
    t.add_row("RA / Dec (ICRS)", f"{_hms(rd['ra_deg'])} / {_dms(rd['dec_deg'])}")
    for ax in ("az", "el"):
        a = st["axes"][ax]
        faults = a.get("fault_text") or str(a["faults"])
        t.add_row(f"{ax} axis", f"{a['state']}, faults: {faults}")
    buf = st["buffer"]
    t.add_row("trajectory buffer", f"{buf.get('points')} points, {buf['free_points']} free, "
                                   f"{buf.get('underruns')} underruns")
    t.add_row("pointing model", st.get("pointing_model") or "none (encoders = observed)")
    op = st.get("operation")
    if op:
        t.add_row("operation", f"#{op['id']} {op['kind']} {shown(op['target'])}: {op['phase']}")
    now = st.get("on_target")
    if now:
        last = now.get("last_sample") or {}
        planned = ", ".join(now.get("planned") or []) or "none planned"
        t.add_row("on target", f"{shown(now['target'])}: the boresight is "
                  f"{_f(now['error_arcsec'], '.3f', '″')} from its true place (az "
                  f"{now['az_deg']:.5f}°, el {now['el_deg']:.5f}°); planned deviation "
                  f"{_f(last.get('planned_deviation_arcsec'), '.3f', '″')} ({planned})")
    for window, s in st.get("tracking_error", {}).items():
        t.add_row(f"errors, last {window}", _window_text(s))
    corr = st.get("corrections") or {}
    if corr:
        axes = (corr.get("offsets") or {}).get("axes") or {}
        axes_text = ", ".join(f"{a} {d.get('total_s', d.get('total_arcsec', 0.0)):+.3f}"
                          f"{' s' if 'total_s' in d else '″'}" for a, d in axes.items())
        t.add_row("offsets", f"{axes_text or 'none'} ({corr.get('mode')}, from "
                             f"{_f(corr.get('min_lead_ms'), 'g', ' ms')} lead)")
    ts = st.get("time_sync", {})
    t.add_row("clock offset", f"{_f(ts.get('offset_us'), 'd', ' µs')} (mount − UTC, from the "
                              f"{ts.get('offset_source') or '-'}; {ts.get('syncs')} PPS syncs, "
                              f"PPS error {_f(ts.get('pps_error_us'), '.0f', ' µs')})")
    if st.get("last_fault"):
        t.add_row("last fault", f"[red]{st['last_fault']}")
    return t


def _window_text(s: dict[str, Any]) -> str:
    """One window of the status's error figures: on target first (the truth), then the
    planned deviation, the encoders' following error and the on-sky figure."""
    if s.get("target_samples"):
        on = (f"on target RMS {_f(s.get('on_target_rms_arcsec'), '.3f', '″')}, peak "
              f"{_f(s.get('on_target_peak_arcsec'), '.3f', '″')}"
              + (f", [red]{s['off_target_s']:.1f} s off target[/]" if s.get("off_target_s")
                 else "")
              + f"; planned deviation peak {_f(s.get('planned_deviation_peak_arcsec'), '.3f', '″')}"
              "; ")
    else:
        on = "no target followed; "
    return (on + f"following RMS {_f(s['rms_arcsec'], '.3f', '″')}, peak "
            f"{_f(s['peak_arcsec'], '.3f', '″')}; on the sky RMS "
            f"{_f(s.get('on_sky_rms_arcsec'), '.3f', '″')}, peak "
            f"{_f(s.get('on_sky_peak_arcsec'), '.3f', '″')}")


def _time_mode(st: dict[str, Any]) -> str:
    mode = st.get("time_mode") or ("paced" if st.get("simulated") else "real time")
    if mode == "real time":
        return "real time"
    speed = st.get("speed")
    return f"{mode} simulated time" + (f" x{speed:g}" if speed else ", as fast as the CPU allows")


def status(server: ServerOpt = None, as_json: JsonOpt = False) -> None:
    """Show encoder and observed position, RA/Dec, axis states, mount time and tracking error."""
    st = ask(server, "status", quiet=as_json)
    if as_json:
        print_json(st)
    else:
        Console().print(render_status(st))
