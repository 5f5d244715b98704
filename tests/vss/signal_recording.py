"""Record emulator signals per tick over an ASTCom stream of the test's own (lockstep rigs).

The test's view of what the mount did is independent of the VSS: its own in-memory
client of the emulator's endpoint, streaming at up to the 10 kHz loop rate.
"""

from __future__ import annotations

import contextlib

import numpy as np


class Recording:
    """Samples received so far: `t_us` (mount µs) and one array per signal name."""

    def __init__(self, names: list[str]) -> None:
        self.names = names
        self._t: list[np.ndarray] = []
        self._v: dict[str, list[np.ndarray]] = {n: [] for n in names}

    def add(self, packet) -> None:
        self._t.append(np.asarray(packet.t_us, np.int64))
        for n in self.names:
            self._v[n].append(np.asarray(packet.column(n), float))

    @property
    def t_us(self) -> np.ndarray:
        return np.concatenate(self._t) if self._t else np.zeros(0, np.int64)

    def __getitem__(self, name: str) -> np.ndarray:
        return np.concatenate(self._v[name]) if self._v[name] else np.zeros(0)


@contextlib.asynccontextmanager
async def recording(vss, names: list[str], rate_hz: float = 10_000.0, *, flush_s: float = 0.5,
                    clock=None):
    """Stream `names` from the embedded emulator while the block runs; yield a `Recording`.

    On leaving, mount time runs `flush_s` longer (on `clock`) so the last packets arrive.
    """
    client = await vss.emulator.connect_in_memory(name="test-recorder")
    stream = await client.stream(names, rate_hz)
    rec = Recording(list(stream.names))
    stream.on_packet(rec.add)
    try:
        yield rec
        if clock is not None:
            await clock.sleep(flush_s)
    finally:
        with contextlib.suppress(Exception):
            await stream.stop()
        await client.close()
