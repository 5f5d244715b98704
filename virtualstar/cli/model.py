"""`vs model load FILE` / `vs model unload`: the pointing model the server applies."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from virtualstar.cli.status import JsonOpt, ServerOpt, ask, print_json

__all__ = ["app"]

app = typer.Typer(help="Load or drop the pointing model the server applies to every target.",
                  no_args_is_help=True, add_completion=False)


@app.command("load")
def load(
    file: Annotated[str, typer.Argument(
        help="Pointing model: JSON (from `pointing-model fit -o model.json`) or a TPOINT "
             ".mod file. A file that exists here is sent as an absolute path; otherwise the path is taken as the server's.")],
    server: ServerOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """Load a pointing model into the server: from now on targets are corrected by it."""
    path = Path(file).expanduser()
    result = ask(server, "load_model",
                 {"path": str(path.resolve()) if path.exists() else file}, quiet=as_json)
    if as_json:
        print_json(result)
        return
    terms = ", ".join(f"{k} {v:+.2f}″" for k, v in result.get("terms", {}).items())
    typer.echo(f"pointing model {result['pointing_model']} loaded: {terms}")


@app.command("unload")
def unload(server: ServerOpt = None, as_json: JsonOpt = False) -> None:
    """Drop the pointing model: targets go to the encoders uncorrected."""
    result = ask(server, "unload_model", quiet=as_json)
    if as_json:
        print_json(result)
    else:
        typer.echo("pointing model unloaded")
