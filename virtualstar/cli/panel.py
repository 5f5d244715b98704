"""`vs panel`: serve the Robot Supervisor Panel to a browser."""

from __future__ import annotations

from typing import Annotated

import typer

from virtualstar.panel import (
    DEFAULT_ENDPOINT,
    DEFAULT_HOST,
    DEFAULT_PORT,
    DEFAULT_VSS,
    PanelConfig,
    PanelError,
    PanelServer,
)

__all__ = ["panel"]


def panel(
    host: Annotated[str, typer.Option(help="Address to listen on (127.0.0.1: this machine only).")] = DEFAULT_HOST,
    port: Annotated[int, typer.Option(min=0, max=65535, help="HTTP port (0 picks a free one).")] = DEFAULT_PORT,
    endpoint: Annotated[str, typer.Option(
        help="ASTCom endpoint the Board tab proposes (ws:// or wss://; the browser connects to it).")] = DEFAULT_ENDPOINT,
    vss: Annotated[str, typer.Option(
        help="VirtualStar Server the Telescope tab proposes (ws:// or wss://). A VSS accepts the "
        "page when it is served from loopback, or when started with --allow-origin and this "
        "panel's http://HOST:PORT.")] = DEFAULT_VSS,
) -> None:
    """Serve the Robot Supervisor Panel; open the printed URL in a browser; Ctrl-C stops."""
    for option, url, what in (("--endpoint", endpoint, "an endpoint"),
                              ("--vss", vss, "a VirtualStar Server")):
        if not url.startswith(("ws://", "wss://")):
            typer.echo(f"vs panel: error: {option} {url!r}: a browser reaches {what} by "
                       "ws://HOST:PORT or wss://HOST:PORT", err=True)
            raise typer.Exit(2)
    try:
        server = PanelServer(PanelConfig(host=host, port=port, endpoint=endpoint, vss=vss))
    except PanelError as exc:
        typer.echo(f"vs panel: error: {exc}", err=True)
        raise typer.Exit(1) from None
    typer.echo(f"Robot Supervisor Panel on {server.url} (endpoint {endpoint}, VSS {vss}); "
               "Ctrl-C stops")
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        pass
    finally:
        server.close()
