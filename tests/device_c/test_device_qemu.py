"""The example firmware (Cortex-M4, astcom_device/port/stm32) on QEMU's netduinoplus2, its
USART on a pty, the Relay on the other side: HELLO, LIST, READ and a stream, checked with
the project's client. The firmware is built by `make -C astcom_device arm`."""

from __future__ import annotations

import asyncio
import re
import subprocess
import sys
from pathlib import Path

import numpy as np

from astcom_client import Client

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "astcom"))
from device_impls import DEVICE_DIR, build_device  # noqa: E402

FIRMWARE = DEVICE_DIR / "build" / "arm" / "example.elf"
PASSWORD = "op-secret"  # FIRMWARE_PASSWORD of port/stm32/firmware.mk


async def _session() -> dict:
    qemu = subprocess.Popen(["qemu-system-arm", "-M", "netduinoplus2", "-kernel", str(FIRMWARE),
                             "-serial", "pty", "-display", "none", "-monitor", "none",
                             "-no-reboot"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)
    relay = None
    try:
        line = await asyncio.to_thread(qemu.stdout.readline)
        pty = re.search(r"(/dev/pts/\d+)", line)
        assert pty, f"QEMU did not give its serial port a pty: {line}"
        relay = subprocess.Popen([sys.executable, "-m", "astcom_client.cli", "relay", "--serial",
                                  pty[1], "--listen", "ws://127.0.0.1:0"],
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        url = re.search(r"(ws://\S+)", await asyncio.to_thread(relay.stdout.readline))[1]
        async with await Client.connect(url, password=PASSWORD, timeout_s=10) as c:
            out = {"hello": c.hello, "entries": await c.list("extra."),
                   "read": await c.read(["mount.tick", "extra.s00", "extra.s03"])}
            stream = await c.stream(["extra.s00", "extra.s03", "mount.tick"], rate_hz=1000)
            out["packets"] = []
            async for packet in stream:
                out["packets"].append(packet)
                if len(out["packets"]) == 10:
                    break
        return out
    finally:
        for proc in (relay, qemu):
            if proc is not None:
                proc.terminate()
                proc.wait(10)


def test_the_firmware_in_qemu_answers_hello_list_read_and_streams_through_the_relay():
    build_device("arm")
    out = asyncio.run(asyncio.wait_for(_session(), 120))
    assert out["hello"]["server"] == "example-stm32" and out["hello"]["loop_rate_hz"] == 10000.0
    names = [e.name for e in out["entries"]]
    assert names == [f"extra.s{i:02d}" for i in range(16)]
    assert all(e.type == "f32" for e in out["entries"])
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
