"""Serve the built Robot Supervisor Panel (static files) and its small config over HTTP.

The browser then speaks ASTCom to the endpoint and JSON to the VirtualStar Server directly;
this server only hands out the bundle and `config.json` (the URLs the Board and Telescope
tabs propose).
"""

from __future__ import annotations

import json
import threading
from dataclasses import dataclass, field
from functools import partial
from http import HTTPStatus
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

from virtualstar.panel.exceptions import BundleMissing, CannotListen

__all__ = ["DEFAULT_ENDPOINT", "DEFAULT_HOST", "DEFAULT_PORT", "DEFAULT_VSS", "STATIC_DIR",
           "PanelConfig", "PanelServer"]

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8080
DEFAULT_ENDPOINT = "ws://127.0.0.1:8765"
DEFAULT_VSS = "ws://127.0.0.1:8740"  # vs server's default --listen (virtualstar.server.DEFAULT_PORT)
STATIC_DIR = Path(__file__).resolve().parent / "static"


@dataclass(frozen=True)
class PanelConfig:
    """Where to listen, which endpoint and VSS the page proposes, where the bundle is."""

    host: str = DEFAULT_HOST
    port: int = DEFAULT_PORT
    endpoint: str = DEFAULT_ENDPOINT
    vss: str = DEFAULT_VSS
    static_dir: Path = field(default=STATIC_DIR)


class _Handler(SimpleHTTPRequestHandler):
    """Static files, plus /config.json; no directory listings, quiet log."""

    config_body: bytes = b"{}"

    def do_GET(self) -> None:  # noqa: N802 (the http.server naming)
        if self.path.split("?", 1)[0] == "/config.json":
            self.send_response(HTTPStatus.OK)
            self.send_header("Content-Type", "application/json")
            self.send_header("Content-Length", str(len(self.config_body)))
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            self.wfile.write(self.config_body)
            return
        super().do_GET()

    def list_directory(self, path):  # type: ignore[override]
        self.send_error(HTTPStatus.NOT_FOUND, "no directory listings")
        return None

    def end_headers(self) -> None:
        if self.path.split("?", 1)[0] in ("/", "/index.html"):
            self.send_header("Cache-Control", "no-cache")
        super().end_headers()

    def log_message(self, format: str, *args: object) -> None:  # noqa: A002
        pass


class PanelServer:
    """An HTTP server of the panel bundle, run in a background thread or in the foreground.

    Raises BundleMissing when the bundle is not built, CannotListen when the port is taken.
    """

    def __init__(self, config: PanelConfig | None = None) -> None:
        self.config = config = config or PanelConfig()
        if not (config.static_dir / "index.html").is_file():
            raise BundleMissing(str(config.static_dir))
        handler = type("PanelHandler", (_Handler,), {
            "config_body": json.dumps({"endpoint": config.endpoint, "vss": config.vss}).encode()})
        try:
            self._httpd = ThreadingHTTPServer((config.host, config.port),
                                              partial(handler, directory=str(config.static_dir)))
        except OSError as exc:
            raise CannotListen(config.host, config.port, exc.strerror or str(exc)) from None
        self._httpd.daemon_threads = True
        self._thread: threading.Thread | None = None

    @property
    def port(self) -> int:
        """The bound port (useful with port 0)."""
        return int(self._httpd.server_address[1])

    @property
    def url(self) -> str:
        """The address to open in a browser."""
        host = self.config.host
        host = f"[{host}]" if ":" in host else host
        return f"http://{host}:{self.port}/"

    def start(self) -> str:
        """Serve in a daemon thread; return the URL."""
        self._thread = threading.Thread(target=self._httpd.serve_forever, name="panel-http",
                                        daemon=True)
        self._thread.start()
        return self.url

    def serve_forever(self) -> None:
        """Serve in this thread until close() or KeyboardInterrupt."""
        self._httpd.serve_forever()

    def close(self) -> None:
        """Stop serving and release the port."""
        if self._thread is not None:
            self._httpd.shutdown()
            self._thread.join()
            self._thread = None
        self._httpd.server_close()

    def __enter__(self) -> PanelServer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
