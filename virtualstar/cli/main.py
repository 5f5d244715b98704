"""Root of the `vs` command line; each command lives in a module of its own.

Commands are imported only when they run (or show their own help): `vs --help` and
`vs status` must not pay for the astronomy, the recorder's Parquet stack or plotting
(benchmarks/bench_cli_startup.py). The table below names each command's module and its
one-line summary for the root help.
"""

from __future__ import annotations

import importlib
from typing import Annotated, Any

import typer
from typer.core import TyperCommand, TyperGroup

__all__ = ["COMMANDS", "app", "main"]

# name: (module, attribute, summary shown by `vs --help`)
COMMANDS: dict[str, tuple[str, str, str]] = {
    "where": ("virtualstar.cli.where", "where",
        "Show where a target is: apparent RA/Dec, observed az/el and rates, "
        "rise/culmination/set."),
    "passes": ("virtualstar.cli.passes", "passes",
        "List satellite passes: rise, culmination (time, elevation) and set; the closest "
        "the pass comes to the Sun; with a horizon profile, when it is above that "
        "profile."),
    "panel": ("virtualstar.cli.panel", "panel",
        "Serve the Robot Supervisor Panel; open the printed URL in a browser; Ctrl-C "
        "stops."),
    "record": ("virtualstar.cli.record", "record",
        "Record NAME... from URL at --rate into --store until --duration or Ctrl-C."),
    "server": ("virtualstar.cli.server", "server",
        "Serve clients (vs status/slew/track/...) until Ctrl-C; the mount is fed "
        "continuously."),
    "alpaca": ("virtualstar.cli.alpaca", "alpaca",
        "Serve an ASCOM Alpaca Telescope (ITelescopeV4) that drives the VirtualStar Server; "
        "Ctrl-C stops."),
    "status": ("virtualstar.cli.status", "status",
        "Show encoder and observed position, RA/Dec, axis states, mount time and tracking "
        "error."),
    "slew": ("virtualstar.cli.slew", "slew",
        "Slew to a target and wait until it lands; a sky target is then tracked until `vs "
        "stop`."),
    "track": ("virtualstar.cli.track", "track",
        "Track a target; returns once tracking has begun (satellite: once the pass is "
        "planned)."),
    "offset": ("virtualstar.cli.offset", "offset",
        "Offset the running track (PWI4-style) on ra, dec, az, el, path or transverse: add, "
        "set, rate or reset; applied gradually from 20 ms after the server accepts it."),
    "stop": ("virtualstar.cli.stop", "stop",
        "Stop the running operation; the mount ramps to rest and holds."),
    "park": ("virtualstar.cli.park", "park",
        "Park the mount (waits until parked)."),
    "watch": ("virtualstar.cli.watch", "watch",
        "Show status and tracking error live; keeps waiting through server restarts."),
    "plan": ("virtualstar.cli.plan", "plan",
        "Plan a night: satellite passes become fixed blocks, sidereal targets fill the gaps "
        "by priority, slews included; every target left out is listed with the reason."),
    "run": ("virtualstar.cli.run", "run",
        "Run a plan block by block through the VSS API: each block's start, delay and slew, "
        "the error on target (boresight vs the target's true place) with the planned "
        "deviation apart, and the outcome (done, degraded, late, missed, faulted); the rest "
        "of the night is planned again after a missed, late or faulted block. Ctrl-C (or "
        "`vs stop`) ends it; --resume goes on."),
    "demo": ("virtualstar.cli.demo", "demo",
        "Run the demo in one process (well under a minute) and print slew times and errors."),
    "pointing-run": ("virtualstar.cli.pointing_run", "pointing_run",
        "Slew to N stars, measure each with the guide camera, write a TPOINT data file."),
    "mode": ("virtualstar.cli.mode", "mode",
        "Switch the server between driving the mount (active) and watching it (passive)."),
    "model": ("virtualstar.cli.model", "app",
        "Load or drop the pointing model the server applies to every target."),
    "data": ("virtualstar.cli.data", "app",
        "Query, plot and export recorded signals."),
    "log": ("virtualstar.cli.log", "log",
        "Print the event log of a store or a VSS (filters: time, level, source, kind, "
        "text; --follow a VSS live)."),
    "experiment": ("virtualstar.cli.experiment", "app",
        "Reproduce the paper's experiments on the mount emulator."),
}


class LazyGroup(TyperGroup):
    """A Typer group that imports a command's module only when that command is used."""

    _listing = False

    def list_commands(self, ctx: Any) -> list[str]:
        return list(COMMANDS)

    def get_command(self, ctx: Any, cmd_name: str) -> Any:
        entry = COMMANDS.get(cmd_name)
        if entry is None:
            return None
        module_name, attribute, summary = entry
        if self._listing:  # the root help only needs the summaries
            return TyperCommand(cmd_name, help=summary, short_help=summary)
        target = getattr(importlib.import_module(module_name), attribute)
        if isinstance(target, typer.Typer):
            command = typer.main.get_group(target)  # a group even with one subcommand
        else:
            single = typer.Typer(add_completion=False)
            # a command may ask for click settings, e.g. negative numbers as arguments
            single.command(cmd_name, context_settings=getattr(target, "context_settings",
                                                              None))(target)
            command = typer.main.get_command(single)
        command.name = cmd_name
        return command

    def format_help(self, ctx: Any, formatter: Any) -> None:
        self._listing = True
        try:
            super().format_help(ctx, formatter)
        finally:
            self._listing = False


app = typer.Typer(
    name="vs",
    cls=LazyGroup,
    help="VirtualStar: point and track an alt-azimuth telescope mount.",
    no_args_is_help=True,
    add_completion=False,
)


@app.callback()
def _root(password: Annotated[str | None, typer.Option(
        "--password", envvar="VS_PASSWORD", show_default=False,
        help="Password of the VirtualStar Server's API, for every client command (vs --password "
             "PW status); the operator password may move the telescope, the observer one only "
             "watch. Not the mount's password (vs server --password).")] = None) -> None:
    from virtualstar.cli.status import set_api_password

    set_api_password(password)


def main() -> None:
    """Run the `vs` command line."""
    app()
