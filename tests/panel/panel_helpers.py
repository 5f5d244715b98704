"""Live processes for the panel tests: an ASTCom endpoint, the node test runners."""

from __future__ import annotations

import asyncio
import json
import os
import re
import shutil
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import forkserver

ROOT = Path(__file__).resolve().parents[2]
PANEL_DIR = ROOT / "panel"
ARTIFACTS = ROOT / "artifacts" / "panel"
CHROMIUM = Path(os.environ.get("CHROMIUM_PATH", "/usr/bin/chromium"))
PASSWORD = "panel-test-secret"
URL_RE = re.compile(r"((?:wss?|tcp)://[^\s)]+)")


class LiveProcess:
    """A child process that prints its ws:// URL on a line; its output is kept for failures."""

    def __init__(self, args: list[str], *, n_urls: int = 1, timeout_s: float = 60.0) -> None:
        self.proc = forkserver.popen(args, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                     text=True, cwd=ROOT)
        self.lines: list[str] = []
        self.urls = self._wait_urls(n_urls, timeout_s)
        self.url = self.urls[0]
        threading.Thread(target=self._drain, daemon=True).start()

    def _wait_urls(self, n_urls: int, timeout_s: float) -> list[str]:
        deadline = time.monotonic() + timeout_s
        urls: list[str] = []
        assert self.proc.stdout is not None
        while time.monotonic() < deadline:
            line = self.proc.stdout.readline()
            if not line:
                break
            self.lines.append(line)
            match = URL_RE.search(line)
            if match:
                urls.append(match.group(1))
                if len(urls) == n_urls:
                    return urls
        self.stop()
        raise RuntimeError("endpoint did not print its URLs:\n" + "".join(self.lines))

    def _drain(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.append(line)

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


def wait_ready(url: str, timeout_s: float = 60.0) -> None:
    """Wait until the endpoint answers a READ (its first loop may still be compiling)."""
    from astcom_client import Client

    async def probe() -> None:
        deadline = time.monotonic() + timeout_s
        while True:
            try:
                async with await Client.connect(url, password=PASSWORD, timeout_s=5.0) as c:
                    await c.read(["mount.tick"])
                    return
            except (ConnectionError, TimeoutError):
                if time.monotonic() > deadline:
                    raise
                await asyncio.sleep(0.5)

    asyncio.run(probe())


def start_emulator() -> LiveProcess:
    """Start the mount emulator (real time, fixed geometry seed) on a free loopback port."""
    code = "from mount_emulator.cli import main; main()"
    emu = LiveProcess([sys.executable, "-c", code, "--port", "0", "--seed", "7",
                       "--password", PASSWORD])
    try:
        wait_ready(emu.url)
    except BaseException:
        emu.stop()
        raise
    return emu


def start_example_device(rate_hz: float) -> LiveProcess:
    """Start astcom_client's example device on free loopback ports: ws:// then tcp://."""
    return LiveProcess([sys.executable, "-m", "astcom_client.example_device", "ws://127.0.0.1:0",
                        "tcp://127.0.0.1:0", "--password", PASSWORD, "--rate", str(rate_hz)],
                       n_urls=2)


def node() -> str:
    """Return the node executable or fail with what to install."""
    path = shutil.which("node")
    if path is None:
        raise RuntimeError("node is not installed: the panel needs Node >= 20 (see setup/30-panel.sh)")
    return path


def ensure_panel_built() -> None:
    """Build the bundle when it is missing (setup/30-panel.sh normally did)."""
    if not (PANEL_DIR / "node_modules").is_dir():
        raise RuntimeError("panel/node_modules is missing: run `bash setup/30-panel.sh`")
    if not (ROOT / "virtualstar" / "panel" / "static" / "index.html").is_file():
        subprocess.run(["npm", "run", "build"], cwd=PANEL_DIR, check=True, capture_output=True)


def ensure_browser_ready() -> None:
    """The bundle built and Debian's chromium present, or the test fails saying what to run."""
    import pytest

    ensure_panel_built()
    if not CHROMIUM.is_file():
        pytest.fail(f"{CHROMIUM} is missing: run `bash setup/30-panel.sh` (installs Debian's chromium)")


@contextmanager
def vss_and_panel(*server_args: str) -> Iterator[dict[str, str]]:
    """Run `vs server --emulator SERVER_ARGS` (tests/vss/vss_rig.py) and `vs panel` proposing
    it; yield the URLs {"vss", "emulator" (its ASTCom endpoint), "panel"}."""
    from vss_rig import vs_server_process

    from virtualstar.panel import PanelConfig, PanelServer

    ensure_browser_ready()
    with vs_server_process("--emulator", *server_args) as server:
        emulator_url = re.search(r"other clients: (ws://\S+?)\)", server.line).group(1)
        with PanelServer(PanelConfig(port=0, endpoint=emulator_url, vss=server.url)) as panel:
            yield {"vss": server.url, "emulator": emulator_url, "panel": panel.start()}


def free_port() -> int:
    """A loopback port free right now (for a process restarted on the same port)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


async def run_asking_script(script: str, env: dict[str, str], actions: dict[str, Callable],
                            *, line_timeout_s: float = 240.0) -> tuple[list[str], str]:
    """Run the node page script `script` (in panel/) that prints "ASK <action>" and waits for
    "done [json]" on stdin: do each action (in a thread; its return value, if any, goes back
    as JSON). Return (the actions done in order, the script's output)."""
    proc = await asyncio.create_subprocess_exec(
        node(), script, cwd=PANEL_DIR, stdin=asyncio.subprocess.PIPE,
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.STDOUT, env=env)
    done: list[str] = []
    out: list[str] = []
    assert proc.stdout is not None and proc.stdin is not None
    while line := (await asyncio.wait_for(proc.stdout.readline(), line_timeout_s)).decode():
        out.append(line)
        if line.startswith("ASK "):
            action = line.split()[1]
            answer = await asyncio.to_thread(actions[action])
            done.append(action)
            proc.stdin.write(f"done {json.dumps(answer) if answer else ''}\n".encode())
            await proc.stdin.drain()
    await proc.wait()
    return done, "".join(out)
