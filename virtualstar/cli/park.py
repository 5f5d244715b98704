"""`vs park`: slew to the park position of the mapping file and power the drives off."""

from __future__ import annotations

from rich.console import Console

from virtualstar.cli.slew import op_table
from virtualstar.cli.status import JsonOpt, ServerOpt, ask, print_json

__all__ = ["park"]


def park(server: ServerOpt = None, as_json: JsonOpt = False) -> None:
    """Park the mount (waits until parked)."""
    op = ask(server, "park", {"wait": True}, progress=True, quiet=as_json)
    if as_json:
        print_json(op)
    else:
        Console().print(op_table(op, "park"))
