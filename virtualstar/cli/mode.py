"""`vs mode active|passive`: let the server drive the mount, or only watch it."""

from __future__ import annotations

from enum import StrEnum
from typing import Annotated

import typer

from virtualstar.cli.status import JsonOpt, ServerOpt, ask, print_json

__all__ = ["mode"]


class Mode(StrEnum):
    active = "active"
    passive = "passive"


def mode(
    which: Annotated[Mode, typer.Argument(
        help="active: commands move the mount; passive: the server only reads status and "
             "tracking errors and sends the mount nothing (TimeS included).")],
    server: ServerOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """Switch the server between driving the mount (active) and watching it (passive)."""
    result = ask(server, "set_mode", {"mode": which.value}, quiet=as_json)
    if as_json:
        print_json(result)
    else:
        typer.echo(f"server {result['mode']}")
