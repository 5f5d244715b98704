"""`vs server --emulator --geometry FILE | --seed N`: the embedded mount gets hidden pointing errors."""

from __future__ import annotations

import asyncio
import math
from pathlib import Path

import pytest
from typer.testing import CliRunner

from astcom_client import Client
from virtualstar.cli.main import app
from virtualstar.launcher import hidden_geometry_arcsec, start_emulator

runner = CliRunner()
GEOMETRY_FILE = Path(__file__).parent / "data" / "hidden-geometry.toml"


@pytest.mark.parametrize(("args", "words"), [
    (["--mount", "ws://127.0.0.1:1", "--seed", "1"], "only apply to --emulator"),
    (["--emulator", "--seed", "1", "--geometry", str(GEOMETRY_FILE)], "not both"),
    (["--emulator", "--geometry", "no-such-geometry.toml"], "no-such-geometry.toml"),
])
def test_bad_geometry_options_exit_with_the_reason_before_serving(args, words):
    result = runner.invoke(app, ["server", *args])
    assert result.exit_code == 2, result.output
    assert words in result.output


def test_a_geometry_file_gives_the_terms_it_holds():
    terms = hidden_geometry_arcsec(path=GEOMETRY_FILE)
    assert terms["ia"] == 150.0 and terms["ie"] == -60.0 and terms["tf"] == 15.0


def test_the_embedded_emulator_with_a_seed_shows_the_guide_camera_a_raw_pointing_error():
    async def body() -> tuple[float, float]:
        terms = hidden_geometry_arcsec(seed=1)
        embedded = await start_emulator(speed=0.0, geometry_arcsec=terms, seeing_arcsec=0.0)
        try:
            async with await Client.connect(embedded.url) as client:
                values = await client.read(["axis.az.position_deg", "axis.el.position_deg"])
                az, el = values["axis.az.position_deg"], values["axis.el.position_deg"]
                # A star exactly where the encoders point: the offset is the hidden error there.
                dx, dy = await client.invoke("guide.measure", az, el)
        finally:
            await embedded.stop()
        return float(dx), float(dy)

    dx, dy = asyncio.run(body())
    assert math.hypot(dx, dy) > 30.0  # a perfect mount would show 0
