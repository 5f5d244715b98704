"""`vs panel`'s HTTP server: serves the bundle and its config, refuses clearly what it cannot do."""

from __future__ import annotations

import json
import socket
import urllib.error
import urllib.request

import pytest
import typer
from panel_helpers import ensure_panel_built
from typer.testing import CliRunner

from virtualstar.cli.panel import panel
from virtualstar.panel import BundleMissing, CannotListen, PanelConfig, PanelServer


@pytest.fixture(scope="module", autouse=True)
def built():
    ensure_panel_built()


def _get(url: str) -> tuple[int, bytes, str]:
    with urllib.request.urlopen(url, timeout=5) as r:
        return r.status, r.read(), r.headers.get("Content-Type", "")


def test_server_serves_the_built_page_its_assets_and_the_endpoint_and_vss_config():
    with PanelServer(PanelConfig(port=0, endpoint="ws://127.0.0.1:9999",
                                 vss="ws://127.0.0.1:9998")) as server:
        server.start()
        status, body, ctype = _get(server.url)
        assert status == 200 and "text/html" in ctype
        assert b'<div id="app">' in body
        script = body.split(b'src="./', 1)[1].split(b'"', 1)[0].decode()
        status, js, ctype = _get(server.url + script)
        assert status == 200 and "javascript" in ctype and len(js) > 10_000
        status, cfg, _ = _get(server.url + "config.json")
        assert json.loads(cfg) == {"endpoint": "ws://127.0.0.1:9999", "vss": "ws://127.0.0.1:9998"}
        # the page names its icon, and it is served (no 404 in the browser's console)
        icon = body.split(b'rel="icon"', 1)[1].split(b'href="./', 1)[1].split(b'"', 1)[0].decode()
        status, svg, ctype = _get(server.url + icon)
        assert status == 200 and ctype.startswith("image/svg+xml") and svg.startswith(b"<svg")


def test_server_refuses_directory_listings_and_unknown_paths():
    with PanelServer(PanelConfig(port=0)) as server:
        server.start()
        for path in ("assets/", "no-such-file.js"):
            with pytest.raises(urllib.error.HTTPError) as info:
                _get(server.url + path)
            assert info.value.code == 404


def test_missing_bundle_names_the_folder_and_the_build_command(tmp_path):
    with pytest.raises(BundleMissing) as info:
        PanelServer(PanelConfig(port=0, static_dir=tmp_path))
    assert str(tmp_path) in str(info.value) and "setup/30-panel.sh" in str(info.value)
    assert isinstance(info.value, FileNotFoundError)


def test_taken_port_is_refused_with_cannot_listen():
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        with pytest.raises(CannotListen) as info:
            PanelServer(PanelConfig(port=port))
        assert f"127.0.0.1:{port}" in str(info.value) and "--port" in str(info.value)


def test_cli_rejects_a_non_websocket_endpoint_or_vss_and_a_taken_port():
    app = typer.Typer()
    app.command("panel")(panel)
    app.command("other")(lambda: None)  # two commands: typer keeps the subcommand name
    runner = CliRunner()
    bad = runner.invoke(app, ["panel", "--endpoint", "tcp://127.0.0.1:8765"])
    assert bad.exit_code == 2 and "ws://HOST:PORT" in bad.output
    bad_vss = runner.invoke(app, ["panel", "--vss", "http://127.0.0.1:8740"])
    assert bad_vss.exit_code == 2 and "--vss" in bad_vss.output and "VirtualStar Server" in bad_vss.output
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        busy = runner.invoke(app, ["panel", "--port", str(taken.getsockname()[1])])
    assert busy.exit_code == 1 and "cannot listen" in busy.output
