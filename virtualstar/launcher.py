"""Start the bundled mount emulator inside this process (`vs server --emulator`, `vs demo`).

This is the only module of `virtualstar` that imports `mount_emulator`
(docs/architecture.md): everything else talks to a mount through ASTCom only.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

__all__ = ["EmbeddedEmulator", "start_emulator"]


@dataclass
class EmbeddedEmulator:
    """A running in-process emulator: its ASTCom URL and the object (to stop it)."""

    url: str
    emulator: Any

    @property
    def mount_time_us(self) -> int:
        return int(self.emulator.model.mount_time_us)

    async def stop(self) -> None:
        await self.emulator.stop()


async def start_emulator(*, speed: float = 1.0, start_us: int | None = None,
                         url: str = "ws://127.0.0.1:0", az_deg: float = 0.0, el_deg: float = 20.0,
                         params: dict[str, float] | None = None,
                         password: str | None = None) -> EmbeddedEmulator:
    """Start the emulator on this event loop and return where it listens.

    speed: 1 real time, X times real time (simulated time); start_us: mount time at
    start (µs since 1970 UTC, None = now). The hidden geometry is the perfect one.
    """
    from mount_emulator import EmulatorConfig, MountEmulator

    config = EmulatorConfig(speed=speed, start_us=start_us, az_deg=az_deg, el_deg=el_deg,
                            params=dict(params or {}),
                            passwords={"operator": password} if password else None)
    emulator = MountEmulator(config)
    emulator.model.run(0)  # compile (or load) the step now, not inside the served loop
    bound = await emulator.start(url)
    return EmbeddedEmulator(bound, emulator)
