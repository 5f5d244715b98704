"""The device implementations the spec-level tests run against, behind one interface.

* ``python``: the Python Endpoint serving astcom_client's ExampleDevice in this process
  (connections in memory, or a URL when a test needs a socket);
* ``c``: the C example controller (astcom_device/, the sanitizer build: ASan + UBSan) as a
  process on loopback TCP; it must exit cleanly, with no sanitizer report and no leak;
* ``c-relay``: the same C device on one end of a pty pair (socat), the Relay
  (``astcom relay --serial``) on the other, the test speaking to the Relay's ws://.

Tests take the ``impl`` name and use ``serve_impl(impl, ...)``; the object it yields
opens raw connections (``connect()``: ``send(bytes)``, ``recv() -> bytes | None``) and
Clients (``client(password)``), whatever is behind.
"""

from __future__ import annotations

import asyncio
import contextlib
import fcntl
import os
import re
import shutil
import struct
import subprocess
import sys
import time
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import forkserver
import pytest
from astcom_helpers import PASSWORDS, served

from astcom_client import Client

ROOT = Path(__file__).resolve().parents[2]
DEVICE_DIR = ROOT / "astcom_device"
BUILDS = {"host": DEVICE_DIR / "build" / "host" / "astcom-example",
          "asan": DEVICE_DIR / "build" / "asan" / "astcom-example"}
SANITIZER_WORDS = ("ERROR: AddressSanitizer", "ERROR: LeakSanitizer", "runtime error:")
ALL_IMPLS = ["python", "c", "c-relay"]
C_IMPLS = ["c", "c-relay"]
# (implementation, URL scheme) pairs of the tests that need a real socket
SOCKET_IMPLS = [("python", "ws"), ("python", "tcp"), ("c", "tcp"), ("c-relay", "ws")]
EXAMPLE_GAINS = [1.0, 0.1, 0.01]  # the example device's gains at start, in both languages


def c_toolchain_missing() -> str | None:
    """Why the C device cannot be built here, or None."""
    for tool in ("make", "gcc"):
        if shutil.which(tool) is None:
            return f"{tool} is not installed (run: bash setup/50-device.sh)"
    for header in ("/usr/include/mpack.h", "/usr/include/msgpack.h", "/usr/include/mbedtls/md.h"):
        if not Path(header).exists():
            return f"{header} is missing (run: bash setup/50-device.sh)"
    return None


_BUILT: set[str] = set()


def build_device(*targets: str) -> None:
    """Build the C device's `targets` once per process (make is incremental; a lock
    serialises pytest-xdist workers).

    Call it from a fixture or a setup hook, never inside a test's timed asyncio run: under
    load a build (or the wait for another worker's build) takes longer than a test's whole
    budget, and the blocked event loop then times out at its first await.
    """
    if _BUILT.issuperset(targets):
        return
    missing = c_toolchain_missing()
    if missing:
        pytest.fail(f"the C device cannot be built: {missing}")
    (DEVICE_DIR / "build").mkdir(exist_ok=True)
    with open(DEVICE_DIR / "build" / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        done = subprocess.run(["make", "-s", "-C", str(DEVICE_DIR), *targets],
                              capture_output=True, text=True, timeout=600)
    if done.returncode:
        pytest.fail(f"building astcom_device failed:\n{done.stdout}\n{done.stderr}")
    _BUILT.update(targets)


def require_built(build: str) -> None:
    """Fail clearly when a test starts a C device its setup did not build."""
    if build not in _BUILT:
        raise RuntimeError(f"the C device's {build!r} build was not made in this test's setup: "
                           f"build it in a fixture (build_device) or take the `impl` parameter")


def device_args(*, passwords: dict[str, str] | None = PASSWORDS, loop_rate_hz: float = 1000.0,
                n_extra_signals: int = 0, **config: Any) -> list[str]:
    """Translate EndpointConfig-style options into the C example's command line."""
    args = ["--rate", f"{loop_rate_hz:g}", "--extra", str(n_extra_signals)]
    if passwords:
        if "operator" in passwords:
            args += ["--password", passwords["operator"]]
        if "observer" in passwords:
            args += ["--observer-password", passwords["observer"]]
    names = {"max_clients": "--max-clients", "max_pending": "--max-pending",
             "auth_timeout_s": "--auth-timeout", "max_frame_bytes": "--max-frame-bytes",
             "max_depth": "--max-depth", "max_array_len": "--max-array-len",
             "max_str_bytes": "--max-str-bytes", "max_messages": "--max-messages",
             "max_names_per_message": "--max-names", "max_streams_per_client": "--max-streams",
             "max_pending_frame_bytes": "--max-pending-frame-bytes",
             "max_pending_frames": "--max-pending-frames"}
    throttle = config.pop("throttle", None)
    if throttle is not None:  # an astcom_client.throttle.ThrottlePolicy
        args += ["--auth-first-delay", f"{throttle.first_delay_s:g}",
                 "--auth-max-delay", f"{throttle.max_delay_s:g}",
                 "--auth-lockout-failures", str(throttle.lockout_failures),
                 "--auth-lockout", f"{throttle.lockout_s:g}",
                 "--auth-forget", f"{throttle.forget_s:g}",
                 "--auth-rate", f"{throttle.global_rate_per_s:g}",
                 "--auth-burst", str(throttle.global_burst),
                 "--auth-max-hold", f"{throttle.max_hold_s:g}",
                 "--auth-addresses", str(min(throttle.max_addresses, 1024))]
    for key, value in config.items():
        if key not in names:
            raise TypeError(f"the C device has no option for {key}")
        args += [names[key], f"{value:g}" if isinstance(value, float) else str(value)]
    return args


class DeviceProcess:
    """A C device process; `stop()` checks it exited cleanly with no sanitizer report."""

    def __init__(self, args: list[str], build: str = "asan") -> None:
        env = dict(os.environ, ASAN_OPTIONS="detect_leaks=1:abort_on_error=0:exitcode=23",
                   UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1:exitcode=24")
        self.proc = subprocess.Popen([str(BUILDS[build]), *args], stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True, env=env)
        self.stdout_lines: list[str] = []

    def wait_line(self, pattern: str, timeout_s: float = 20.0) -> re.Match:
        deadline = time.monotonic() + timeout_s
        assert self.proc.stdout is not None
        while time.monotonic() < deadline:
            line = self.proc.stdout.readline()
            if not line:
                break
            self.stdout_lines.append(line)
            if m := re.search(pattern, line):
                return m
        self.proc.kill()
        raise RuntimeError(f"the C device did not print {pattern!r}: "
                           f"{''.join(self.stdout_lines)} {self.proc.stderr.read()}")

    def stop(self) -> str:
        """Terminate; return stderr; fail on a crash, a sanitizer report or a leak."""
        if self.proc.poll() is None:
            self.proc.terminate()
        try:
            _, err = self.proc.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            _, err = self.proc.communicate()
            pytest.fail(f"the C device did not stop on SIGTERM\n{err}")
        if any(word in err for word in SANITIZER_WORDS) or self.proc.returncode not in (0,):
            pytest.fail(f"the C device exited with {self.proc.returncode}:\n{err[-6000:]}")
        return err


class TcpRaw:
    """A raw length-prefixed TCP connection (§1), for tests that write frames by hand."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.reader, self.writer = reader, writer

    async def send(self, frame: bytes) -> None:
        self.writer.write(struct.pack(">I", len(frame)) + frame)
        await self.writer.drain()

    async def recv(self) -> bytes | None:
        try:
            head = await self.reader.readexactly(4)
            return await self.reader.readexactly(struct.unpack(">I", head)[0])
        except (asyncio.IncompleteReadError, ConnectionError):
            return None

    async def close(self, code: int = 1000, reason: str = "") -> None:
        self.writer.close()


class WsRaw:
    """A raw WebSocket connection: one binary message per frame."""

    def __init__(self, ws: Any) -> None:
        self.ws = ws

    async def send(self, frame: bytes) -> None:
        await self.ws.send(frame)

    async def recv(self) -> bytes | None:
        import websockets

        try:
            return await self.ws.recv()
        except websockets.ConnectionClosed:
            return None

    async def close(self, code: int = 1000, reason: str = "") -> None:
        await self.ws.close()


class DeviceUnderTest:
    """What a spec-level test needs from a device, whatever implements it."""

    def __init__(self, impl: str, url: str | None, endpoint: Any = None, device: Any = None) -> None:
        self.impl, self.url, self.endpoint, self.device = impl, url, endpoint, device
        self._raws: list[Any] = []
        # a C device's stderr, once it has stopped (its log: "auth: wrong password from ...")
        self.log = ""

    async def connect(self) -> Any:
        """Open a raw connection (send/recv whole frames)."""
        if self.endpoint is not None and self.url is None:
            return self.endpoint.connect_in_memory()
        if self.url.startswith("tcp://"):
            host, port = self.url.removeprefix("tcp://").rsplit(":", 1)
            raw: Any = TcpRaw(*await asyncio.open_connection(host, int(port)))
        else:
            from websockets.asyncio.client import connect

            raw = WsRaw(await connect(self.url, proxy=None, compression=None, max_size=None))
        self._raws.append(raw)
        return raw

    async def client(self, password: str | None = PASSWORDS["operator"], **kwargs: Any) -> Client:
        if self.endpoint is not None and self.url is None:
            return await Client.open(self.endpoint.connect_in_memory(), password=password, **kwargs)
        return await Client.connect(self.url, password=password, **kwargs)

    async def start_t_us(self, loop_rate_hz: float) -> int:
        """The mount time of tick 0."""
        if self.device is not None:
            return self.device.start_t_us
        async with await self.client() as c:
            while (ping := await c.ping())["tick"] < 0:
                await asyncio.sleep(0.01)
        return ping["tick_t_us"] - round(ping["tick"] * 1e6 / loop_rate_hz)

    async def aclose(self) -> None:
        for raw in self._raws:
            with contextlib.suppress(Exception):
                await raw.close()


@contextlib.asynccontextmanager
async def serve_impl(impl: str, *, scheme: str | None = None, realtime: bool = False,
                     **config: Any) -> AsyncIterator[DeviceUnderTest]:
    """Serve the example device of `impl` (see the module docstring) with `config`.

    `scheme` ("ws"/"tcp") makes the Python endpoint listen on loopback (else connections
    are in memory); the C device always listens on TCP, the Relay on ws://.
    """
    if impl == "python":
        url = f"{scheme}://127.0.0.1:0" if scheme else None
        async with served(url, realtime=realtime, **config) as (device, endpoint, bound):
            dut = DeviceUnderTest(impl, bound, endpoint, device)
            try:
                yield dut
            finally:
                await dut.aclose()
        return
    require_built("asan")
    if impl == "c":
        proc = DeviceProcess(["--tcp", "127.0.0.1:0", *device_args(**config)])
        dut = None
        try:
            url = proc.wait_line(r"(tcp://\S+)")[1]
            dut = DeviceUnderTest(impl, url)
            try:
                yield dut
            finally:
                await dut.aclose()
        finally:
            log = await asyncio.to_thread(proc.stop)
            if dut is not None:
                dut.log = log
        return
    if impl == "c-relay":
        logs: list[str] = []
        dut = None
        try:
            async with relayed_device(device_args(**config), logs=logs) as url:
                dut = DeviceUnderTest(impl, url)
                try:
                    yield dut
                finally:
                    await dut.aclose()
        finally:
            if dut is not None:
                dut.log = "".join(logs)
        return
    raise ValueError(f"unknown device implementation {impl!r}")


@contextlib.asynccontextmanager
async def relayed_device(args: list[str], build: str = "asan", relay_args: tuple[str, ...] = (),
                         logs: list[str] | None = None) -> AsyncIterator[str]:
    """A C device on a pty pair (socat), the Relay on the other end; yield the Relay's URL.
    The device's stderr is appended to `logs` once it has stopped."""
    if shutil.which("socat") is None:
        pytest.fail("socat is not installed (run: bash setup/50-device.sh)")
    require_built(build)
    with pty_pair() as (dev_end, relay_end):
        proc = DeviceProcess(["--serial", dev_end, *args], build=build)
        relay = forkserver.popen([sys.executable, "-m", "astcom_client.cli", "relay", "--serial",
                                  relay_end, "--listen", "ws://127.0.0.1:0", *relay_args],
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            proc.wait_line(r"link on")
            line = await asyncio.to_thread(relay.stdout.readline)
            m = re.search(r"(ws://\S+)", line)
            if not m:
                relay.kill()
                raise RuntimeError(f"the relay did not start: {line} {relay.stderr.read()}")
            yield m[1]
        finally:
            relay.terminate()
            with contextlib.suppress(subprocess.TimeoutExpired):
                relay.wait(10)
            log = await asyncio.to_thread(proc.stop)
            if logs is not None:
                logs.append(log)


@contextlib.contextmanager
def pty_pair():
    """Two linked ptys from socat; yield their paths."""
    import tempfile

    d = tempfile.mkdtemp(prefix="astcom-pty-")
    a, b = f"{d}/device", f"{d}/relay"
    proc = subprocess.Popen(["socat", f"pty,raw,echo=0,link={a}", f"pty,raw,echo=0,link={b}"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 10
        while not (os.path.exists(a) and os.path.exists(b)):
            if time.monotonic() > deadline or proc.poll() is not None:
                raise RuntimeError("socat did not create the pty pair")
            time.sleep(0.01)
        yield a, b
    finally:
        proc.terminate()
        proc.wait(10)
        shutil.rmtree(d, ignore_errors=True)
