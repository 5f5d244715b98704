"""Root of the `vs` command line; each command lives in a module of its own."""

import typer

app = typer.Typer(
    name="vs",
    help="VirtualStar: point and track an alt-azimuth telescope mount.",
    no_args_is_help=True,
    add_completion=False,
)


def main() -> None:
    """Run the `vs` command line."""
    app()
