"""Root of the `vs` command line; each command lives in a module of its own."""

import typer

app = typer.Typer(
    name="vs",
    help="VirtualStar: point and track an alt-azimuth telescope mount.",
    no_args_is_help=True,
    add_completion=False,
)

from virtualstar.cli import panel as _panel  # noqa: E402
from virtualstar.cli import passes as _passes  # noqa: E402
from virtualstar.cli import where as _where  # noqa: E402

app.command("where")(_where.where)
app.command("passes")(_passes.passes)
app.command("panel")(_panel.panel)


def main() -> None:
    """Run the `vs` command line."""
    app()
