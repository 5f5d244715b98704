"""Start the bundled mount emulator inside this process (`vs server --emulator`, `vs demo`).

This is the only module of `virtualstar` that imports `mount_emulator`
(docs/architecture.md): everything else talks to a mount through ASTCom only.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = ["EmbeddedEmulator", "hidden_geometry_arcsec", "start_emulator"]


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


def hidden_geometry_arcsec(*, path: str | Path | None = None,
                           seed: int | None = None) -> dict[str, float]:
    """Return the emulator's hidden TPOINT terms (arcsec) from a TOML/JSON file or a seed.

    The same rules as `mount-emulator --geometry FILE | --seed N`. Raises ValueError
    naming the file or the option when it cannot be used.
    """
    from mount_emulator import Geometry
    from mount_emulator.exceptions import ConfigError

    if path is not None and seed is not None:
        raise ValueError("give either a geometry file or a seed, not both")
    try:
        geometry = Geometry.from_file(path) if path is not None else Geometry.from_seed(int(seed or 0))
    except ConfigError as exc:
        raise ValueError(str(exc)) from None
    return geometry.as_dict()


async def start_emulator(*, speed: float = 1.0, start_us: int | None = None,
                         url: str = "ws://127.0.0.1:0", az_deg: float = 0.0, el_deg: float = 20.0,
                         params: dict[str, float] | None = None,
                         password: str | None = None,
                         geometry_arcsec: dict[str, float] | None = None,
                         seeing_arcsec: float | None = None) -> EmbeddedEmulator:
    """Start the emulator on this event loop and return where it listens.

    speed: 1 real time, X times real time (simulated time); start_us: mount time at
    start (µs since 1970 UTC, None = now); geometry_arcsec: the hidden TPOINT terms
    ({"ia": 120.0, ...}, default perfect); seeing_arcsec: guide-camera noise.
    """
    from mount_emulator import EmulatorConfig, Geometry, MountEmulator, MountModel

    # compile (or load) the step before the emulator takes its start time: in real time
    # its clock then starts within milliseconds of UTC, not a compile later
    MountModel(start_us=0).run(0)

    extra = {}
    if geometry_arcsec:
        extra["geometry"] = Geometry.from_mapping(geometry_arcsec, where="geometry_arcsec")
    if seeing_arcsec is not None:
        extra["seeing_arcsec"] = seeing_arcsec
    config = EmulatorConfig(speed=speed, start_us=start_us, az_deg=az_deg, el_deg=el_deg,
                            params=dict(params or {}),
                            passwords={"operator": password} if password else None, **extra)
    emulator = MountEmulator(config)
    bound = await emulator.start(url)
    return EmbeddedEmulator(bound, emulator)
