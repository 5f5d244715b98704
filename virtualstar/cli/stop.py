"""`vs stop`: end any slew or track and bring the mount to rest."""

from __future__ import annotations

from typing import Annotated

import typer

from virtualstar.cli.status import JsonOpt, ServerOpt, ask, print_json

__all__ = ["stop"]


def stop(
    reset_faults: Annotated[bool, typer.Option(
        "--reset-faults", help="Also clear the mount's latched faults (the axes go to off).")] = False,
    server: ServerOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """Stop the running operation; the mount ramps to rest and holds."""
    result = ask(server, "stop", {"reset_faults": reset_faults}, quiet=as_json)
    if as_json:
        print_json(result)
    else:
        typer.echo(f"stopped; mount {result['mount_state']}")
