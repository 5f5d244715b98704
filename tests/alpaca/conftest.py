"""An emulator + VSS rig (lockstep, paced) with the Alpaca façade on loopback, for alpyca.

Night at Poznań (2024-05-18 21:00 UTC) for the telescope tests; a daytime rig for the
Sun zone. The façade talks to the VSS in-process (`LocalVssClient`); alpyca talks HTTP.
"""

from __future__ import annotations

import contextlib
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parents[1] / "vss"))

from vss_rig import Rig  # noqa: E402

from virtualstar.astro import UtcTimes, load_site  # noqa: E402

NIGHT = "2024-05-18T21:00:00Z"
DAY = "2024-05-18T10:00:00Z"


class AlpacaRig:
    def __init__(self, start_iso: str) -> None:
        from virtualstar.alpaca import serve_alpaca
        from virtualstar.server.local_client import LocalVssClient

        start_us = int(UtcTimes.from_iso([start_iso]).to_unix_us()[0])
        self.rig = Rig(start_us=start_us, site=load_site()).start()

        async def serve():
            return await serve_alpaca(LocalVssClient(self.rig.server), port=0,
                                      discovery_bind=None)

        self.service = self.rig.run(serve())
        self.address = self.service.url.removeprefix("http://")
        self.site = self.rig.site

    def telescope(self, connect: bool = True):
        from alpaca.telescope import Telescope

        t = Telescope(self.address, 0)
        if connect:
            t.Connected = True
        return t

    def on_loop(self, fn, *args):
        """Call `fn(*args)` on the rig's loop and wait for it: a change of the clock made from
        the test's thread has taken effect when this returns (a call merely scheduled could
        still be pending when the next block reads the clock)."""
        async def call():
            return fn(*args)

        return self.rig.run(call())

    @contextlib.contextmanager
    def frozen(self):
        """Mount time stands still inside the block (a check right after a command sees the
        operation as it began, however slow the host): the rig's clock, frozen on its loop."""
        clock = self.rig.clock
        self.on_loop(clock.freeze)
        try:
            yield
        finally:
            self.on_loop(clock.thaw)

    @contextlib.contextmanager
    def paced(self, pace: float):
        """Mount time at most `pace` × wall time inside the block (room for a stalled host)."""
        clock = self.rig.clock
        before = self.on_loop(lambda: clock.pace)
        self.on_loop(clock.set_pace, pace)
        try:
            yield
        finally:
            self.on_loop(clock.set_pace, before)

    def close(self) -> None:
        self.rig.run(self.service.close())
        self.rig.close()


@pytest.fixture(scope="module")
def night():
    r = AlpacaRig(NIGHT)
    yield r
    r.close()


@pytest.fixture(scope="module")
def day():
    r = AlpacaRig(DAY)
    yield r
    r.close()
