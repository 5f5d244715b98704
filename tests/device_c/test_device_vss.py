"""`vs server --mount` slews to and tracks Vega on the C example's follower, given
astcom_device/examples/follower-mapping.json, in real time (the C device runs on the
host clock and the VSS keeps its mount clock on host UTC).

The encoders are read straight from the device (READ at one tick: values and that tick's
mount time) and compared with astropy's observed Vega at that time, for a site chosen
when the test starts so that Vega is high (about 60 degrees, near the meridian) whatever
the hour. The follower is an ideal servo on the VSS's trajectory and no pointing model is
loaded, so the encoders must be the observed place.
"""

from __future__ import annotations

import asyncio
import json
import sys
import time
from pathlib import Path

import numpy as np
from astcom_helpers import PASSWORDS
from astropy.utils import iers
from device_impls import DEVICE_DIR, DeviceProcess, device_args
from typer.testing import CliRunner

from astcom_client import Client
from virtualstar.astro import Site
from virtualstar.cli.main import app

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "vss"))
from sky_truth import sky_sep_arcsec, vega_truth  # noqa: E402
from vss_rig import vs_server_process  # noqa: E402

iers.conf.auto_max_age = None  # the host's date may lie in the table's predictions
MAPPING = DEVICE_DIR / "examples" / "follower-mapping.json"
VEGA_RA_DEG, VEGA_DEC_DEG = 279.2347, 38.7837
ONE_ARCSEC = 1.0
runner = CliRunner()


def site_with_vega_high(now_s: float) -> Site:
    """A site where Vega is about 60 degrees up, 15 degrees east of its meridian, now."""
    from astropy.time import Time

    gmst_deg = Time(now_s, format="unix").sidereal_time("mean", "greenwich").deg
    hour_angle_deg = -15.0
    lon_deg = (VEGA_RA_DEG + hour_angle_deg - gmst_deg + 180.0) % 360.0 - 180.0
    return Site(lat_deg=VEGA_DEC_DEG - 30.0, lon_deg=lon_deg, height_m=100.0)


def vs(*args: str) -> dict:
    res = runner.invoke(app, [*args, "--json"])
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout)


async def encoders_vs_vega(url: str, site: Site, n: int = 5) -> np.ndarray:
    """On-sky distances (arcsec) between the encoders and astropy's Vega, n reads."""
    names = ["axis.az.position", "axis.el.position"]
    reads = []
    async with await Client.connect(url, password=PASSWORDS["observer"]) as client:
        for _ in range(n):
            values, _tick, t_us = await client.read_at(names)
            reads.append((values, int(t_us)))
            await asyncio.sleep(0.2)
    t = np.array([r[1] for r in reads])
    az = np.degrees([r[0][names[0]] for r in reads]) % 360.0
    el = np.degrees([r[0][names[1]] for r in reads])
    taz, tel = vega_truth(t, site)
    return sky_sep_arcsec(az, el, taz, tel)


async def quicken_the_slews(url: str) -> None:
    """Raise the follower's slew limits (20 deg/s, 20 deg/s2) before the VSS reads them."""
    limits = {f"axis.{axis}.{name}": np.radians(20.0) for axis in ("az", "el")
              for name in ("rate_limit", "accel_limit")}
    async with await Client.connect(url, password=PASSWORDS["operator"]) as client:
        await client.write(limits)


def wait_for_the_mount(vss_url: str, timeout_s: float = 60.0) -> dict:
    deadline = time.monotonic() + timeout_s
    while True:
        status = vs("status", "--server", vss_url)
        if status["connected"] and status["time_sync"]["syncs"]:
            return status
        assert time.monotonic() < deadline, status
        time.sleep(0.5)


def test_vs_server_slews_to_and_tracks_vega_on_the_c_follower(host_device):
    site = site_with_vega_high(time.time())
    device = DeviceProcess(["--tcp", "127.0.0.1:0", *device_args(loop_rate_hz=1000.0)],
                           build="host")
    try:
        mount_url = device.wait_line(r"(tcp://\S+)")[1]
        asyncio.run(quicken_the_slews(mount_url))
        with vs_server_process("--mount", mount_url, "--password", PASSWORDS["operator"],
                               "--mapping", str(MAPPING),
                               f"--site={site.lat_deg},{site.lon_deg},{site.height_m}") as vss:
            status = wait_for_the_mount(vss.url)
            limits = status["limits"]  # read from the device
            assert limits["wrap_max_deg"] == 270.0 and limits["az_max_rate_deg_s"] == 20.0
            op = vs("slew", "--star", "Vega", "--server", vss.url)
            assert op["phase"] == "tracking", op
            assert 55.0 < op["info"]["to_el_deg"] < 65.0
            landed = asyncio.run(encoders_vs_vega(mount_url, site, 3))
            assert landed.max() < ONE_ARCSEC, landed
            time.sleep(2.0)  # it follows the star, not the place where it landed
            tracking = asyncio.run(encoders_vs_vega(mount_url, site, 5))
            assert tracking.max() < ONE_ARCSEC, tracking
            assert vs("status", "--server", vss.url)["mount_state"] == "tracking"
            assert vs("stop", "--server", vss.url)["mount_state"] == "holding"
    finally:
        device.stop()
