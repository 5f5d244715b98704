"""The panel's smoke test against the C example device (astcom_device, -O2 build) behind the
Relay, in headless chromium: connect (a whole LIST through the framed link), call a
function, stream and plot, compute, write a parameter, read STATS. The page script is
panel/test/e2e/device.e2e.mjs; this test checks what it did with the Python client and
against the device's known signals (extra.s00 = sin(2*pi*5 Hz*t), counter = tick)."""

from __future__ import annotations

import asyncio
import json
import sys
from pathlib import Path

from panel_helpers import ARTIFACTS, CHROMIUM, PANEL_DIR, ensure_browser_ready, node

from astcom_client import Client
from virtualstar.panel import PanelConfig, PanelServer

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "astcom"))
from device_impls import build_device, relayed_device  # noqa: E402

PASSWORD = "panel-c-device"
PARAM_NAME, PARAM_VALUE = "wave.amplitude", "2.5"


async def run_page(panel_url: str, device_url: str, result_path: Path) -> tuple[dict, float]:
    proc = await asyncio.create_subprocess_exec(
        node(), "test/e2e/device.e2e.mjs", cwd=PANEL_DIR, stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.STDOUT,
        env={"PATH": "/usr/bin:/bin:/usr/local/bin", "HOME": str(result_path.parent),
             "PANEL_URL": panel_url, "ASTCOM_URL": device_url, "ASTCOM_PASSWORD": PASSWORD,
             "ARTIFACTS": str(ARTIFACTS), "RESULT": str(result_path),
             "PARAM_NAME": PARAM_NAME, "PARAM_VALUE": PARAM_VALUE,
             "CHROMIUM_PATH": str(CHROMIUM)})
    out, _ = await asyncio.wait_for(proc.communicate(), timeout=180)
    result = json.loads(result_path.read_text()) if result_path.exists() else {}
    result["log"] = out.decode(errors="replace")
    async with await Client.connect(device_url, password=PASSWORD) as client:
        read_back = (await client.read([PARAM_NAME]))[PARAM_NAME]
        result["entries_by_client"] = len(await client.list())
    return result, read_back


def test_the_panel_drives_the_c_device_through_the_relay(tmp_path):
    ensure_browser_ready()
    build_device("host")

    async def main():
        args = ["--password", PASSWORD, "--rate", "1000", "--extra", "16"]
        async with relayed_device(args, build="host") as url:
            with PanelServer(PanelConfig(port=0)) as panel:
                return await run_page(panel.start(), url, tmp_path / "result.json")

    result, read_back = asyncio.run(main())
    assert result.get("ok"), f"{result.get('error')}\n{result.get('log')}"
    assert not result.get("pageErrors"), result["pageErrors"]
    assert result["entries"] == result["entries_by_client"] > 70
    assert abs(result["nowUs"] - result["hostUs"]) < 60e6  # the device's clock is the host's
    check = result["computeCheck"]
    assert check["n"] >= 200 and check["worst"] < 1e-9
    assert result["paramShown"].strip() == PARAM_VALUE and read_back == float(PARAM_VALUE)
    assert result["stream"]["samples"] > 0 and result["stream"]["lost"] == 0
