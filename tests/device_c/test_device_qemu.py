"""The example firmware (Cortex-M4, astcom_device/port/stm32) on QEMU's netduinoplus2, its
USART on a pty, the Relay on the other side: HELLO, a whole LIST (larger than the
firmware's 1 KiB reply scratch: it goes out in parts), READ and a stream, checked with the
project's client (after a wrong password: the throttle's path). Afterwards QEMU's monitor reads the firmware's memory: the arena and link
sizes it was built with are what the library says it needs, and the stack (painted at
reset) kept a margin. The firmware is built by `make -C astcom_device arm`."""

from __future__ import annotations

import asyncio
import re
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import forkserver
import numpy as np

from astcom_client import AstcomError, Client
from astcom_client.exceptions import AuthenticationFailed

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "astcom"))
from device_impls import DEVICE_DIR, build_device  # noqa: E402

FIRMWARE = DEVICE_DIR / "build" / "arm" / "example.elf"
PASSWORD = "op-secret"  # FIRMWARE_PASSWORD of port/stm32/firmware.mk


STACK_MARGIN_BYTES = 512


def symbols() -> dict[str, int]:
    """Addresses of the firmware's symbols (arm-none-eabi-nm)."""
    out = subprocess.run(["arm-none-eabi-nm", str(FIRMWARE)], capture_output=True, text=True,
                         check=True).stdout
    return {f[2]: int(f[0], 16) for f in (line.split() for line in out.splitlines()) if len(f) == 3}


def read_words(monitor: str, address: int, count: int) -> list[int]:
    """Words of the guest's memory, through QEMU's monitor (its `xp` command)."""
    with socket.socket(socket.AF_UNIX) as sock:
        sock.connect(monitor)
        sock.settimeout(5)
        sock.sendall(f"xp /{count}wx {address:#x}\n".encode())
        text, deadline = b"", time.monotonic() + 10
        while text.count(b"\n(qemu)") < 2 and time.monotonic() < deadline:
            text += sock.recv(1 << 16)
    words = re.findall(r"^[0-9a-f]+:\s+((?:0x[0-9a-f]+\s*)+)$", text.decode(errors="replace"),
                       re.MULTILINE)
    values = [int(w, 16) for line in words for w in line.split()]
    assert len(values) == count, text[-500:]
    return values


async def _session(monitor: str) -> dict:
    qemu = subprocess.Popen(["qemu-system-arm", "-M", "netduinoplus2", "-kernel", str(FIRMWARE),
                             "-serial", "pty", "-display", "none",
                             "-monitor", f"unix:{monitor},server,nowait", "-no-reboot"],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    relay = None
    try:
        line = await asyncio.to_thread(qemu.stdout.readline)
        pty = re.search(r"(/dev/pts/\d+)", line)
        assert pty, f"QEMU did not give its serial port a pty: {line}"
        # an emulated MCU on a loaded host may stall for seconds: a patient relay
        relay = forkserver.popen([sys.executable, "-m", "astcom_client.cli", "relay", "--serial",
                                  pty[1], "--listen", "ws://127.0.0.1:0", "--link-timeout", "30"],
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        line = await asyncio.to_thread(relay.stdout.readline)
        url = re.search(r"(ws://\S+)", line)[1]
        if "link up" not in line:  # the firmware did not start: its memory, most likely
            sym = symbols()
            link, arena = read_words(monitor, sym["fw_link_needed"], 2)
            raise AssertionError(f"the firmware does not answer ({line.strip()}); it needs "
                                 f"an arena of {arena} and a link of {link} bytes "
                                 "(FW_ARENA_BYTES, FW_LINK_BYTES in firmware.mk)")
        # a wrong password first: its ERR 401 comes from the throttle's path (§10), and the
        # right one after it is held 0.25 s and answered from the firmware's poll loop
        try:
            await (await Client.connect(url, password="not-" + PASSWORD, timeout_s=10)).close()
            wrong = "accepted"
        except AuthenticationFailed as exc:
            wrong = str(exc)
        async with await Client.connect(url, password=PASSWORD, timeout_s=10) as c:
            out = {"hello": c.hello, "entries": await c.list(), "wrong": wrong,
                   "read": await c.read(["mount.tick", "extra.s00", "extra.s03"])}
            stream = await c.stream(["extra.s00", "extra.s03", "mount.tick"], rate_hz=1000)
            out["packets"] = []
            async for packet in stream:
                out["packets"].append(packet)
                if len(out["packets"]) == 10:
                    break
            await stream.stop()
            # the deeper paths, for the stack's high-water mark: a call with arrays, errors
            # with texts (numbers formatted by the library, a name hint)
            out["sum"] = await c.invoke("math.add", 1.5, 2.25)
            t0 = (await c.read(["time.mount_us"]))["time.mount_us"] + 1_000_000
            n = 40
            out["accepted"] = await c.invoke(
                "traj.push_rates", t0 + 50_000 * np.arange(n, dtype=np.int64),
                np.zeros(n), np.full(n, 1.0), np.zeros(n), np.zeros(n))
            out["errors"] = []
            for bad in (c.write({"wave.amplitude": 1000.0}), c.read(["wave.amplitud"])):
                try:
                    await bad
                except AstcomError as exc:
                    out["errors"].append(str(exc))
        sym = symbols()
        out["needed"] = read_words(monitor, sym["fw_link_needed"], 2)  # link, then arena
        stack = read_words(monitor, sym["_stack_bottom"],
                           (sym["_stack_top"] - sym["_stack_bottom"]) // 4)
        out["stack_unused"] = 4 * next(i for i, w in enumerate(stack) if w != 0xA5A5A5A5)
        out["stack_bytes"] = 4 * len(stack)
        return out
    finally:
        for proc in (relay, qemu):
            if proc is not None:
                proc.terminate()
                proc.wait(10)


def test_the_firmware_in_qemu_answers_hello_list_read_and_streams_through_the_relay():
    build_device("arm")
    with tempfile.TemporaryDirectory() as tmp:
        out = asyncio.run(asyncio.wait_for(_session(f"{tmp}/monitor"), 120))
    assert out["hello"]["server"] == "example-stm32" and out["hello"]["loop_rate_hz"] == 10000.0
    assert "wrong password" in out["wrong"], out["wrong"]
    entries = {e.name: e for e in out["entries"]}
    assert len(entries) > 70  # every variable and function: about 5 KiB of LIST
    assert [n for n in entries if n.startswith("extra.")] == [f"extra.s{i:02d}" for i in range(16)]
    assert all(entries[f"extra.s{i:02d}"].type == "f32" for i in range(16))
    assert entries["traj.push_rates"].kind == "function" and "mount.slew" in entries
    assert out["sum"] == 3.75 and out["accepted"] == 40
    assert "wave.amplitude = 1000 V is above its maximum 100 V" in out["errors"][0]
    assert "did you mean wave.amplitude?" in out["errors"][1]
    assert out["read"]["mount.tick"] > 0
    packets = out["packets"]
    for prev, nxt in zip(packets, packets[1:], strict=False):  # no gap, no loss
        assert nxt.first_tick == prev.first_tick + prev.n * prev.period_ticks
    for p in packets:
        ticks = p.first_tick + p.period_ticks * np.arange(p.n)
        assert p.period_ticks == 10 and np.all(ticks % 10 == 0)
        # the firmware's extras are sinf(2*pi*5 Hz*t + i) in single precision
        phase = 2 * np.pi * 5.0 * ticks / 10_000.0
        np.testing.assert_allclose(p.column("extra.s00"), np.sin(phase), atol=2e-5)
        np.testing.assert_allclose(p.column("extra.s03"), np.sin(phase + 3), atol=2e-5)
    # the memory it was built with holds what the library says it needs, and not much more
    # (firmware.mk: a struct that grows needs FW_ARENA_BYTES raised)
    text = (DEVICE_DIR / "port" / "stm32" / "firmware.mk").read_text()
    built = {k: int(v) for k, v in re.findall(r"-DFW_(ARENA|LINK)_BYTES=(\d+)u", text)}
    for name, needed in zip(("LINK", "ARENA"), out["needed"], strict=True):
        assert 0 <= built[name] - needed <= 256, (name, needed, built[name])
    print(f"firmware stack: {out['stack_bytes'] - out['stack_unused']} of {out['stack_bytes']} bytes used")
    assert out["stack_unused"] >= STACK_MARGIN_BYTES, out["stack_unused"]
