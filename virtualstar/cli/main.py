"""Root of the `vs` command line; each command lives in a module of its own."""

from typing import Annotated

import typer

app = typer.Typer(
    name="vs",
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

from virtualstar.cli import data as _data  # noqa: E402
from virtualstar.cli import demo as _demo  # noqa: E402
from virtualstar.cli import experiment as _experiment  # noqa: E402
from virtualstar.cli import mode as _mode  # noqa: E402
from virtualstar.cli import model as _model  # noqa: E402
from virtualstar.cli import panel as _panel  # noqa: E402
from virtualstar.cli import park as _park  # noqa: E402
from virtualstar.cli import passes as _passes  # noqa: E402
from virtualstar.cli import pointing_run as _pointing_run  # noqa: E402
from virtualstar.cli import record as _record  # noqa: E402
from virtualstar.cli import server as _server  # noqa: E402
from virtualstar.cli import slew as _slew  # noqa: E402
from virtualstar.cli import status as _status  # noqa: E402
from virtualstar.cli import stop as _stop  # noqa: E402
from virtualstar.cli import track as _track  # noqa: E402
from virtualstar.cli import watch as _watch  # noqa: E402
from virtualstar.cli import where as _where  # noqa: E402

app.command("where")(_where.where)
app.command("passes")(_passes.passes)
app.command("panel")(_panel.panel)
app.command("record")(_record.record)
app.command("server")(_server.server)
app.command("status")(_status.status)
app.command("slew")(_slew.slew)
app.command("track")(_track.track)
app.command("stop")(_stop.stop)
app.command("park")(_park.park)
app.command("watch")(_watch.watch)
app.command("demo")(_demo.demo)
app.command("pointing-run")(_pointing_run.pointing_run)
app.command("mode")(_mode.mode)
app.add_typer(_model.app, name="model")
app.add_typer(_data.app, name="data")
app.add_typer(_experiment.app, name="experiment")


def main() -> None:
    """Run the `vs` command line."""
    app()
