"""The VSS's client of a guide camera device: the frames read out since the last one seen.

A guide camera is an ASTCom device of its own (the simulator in `guide_camera/`,
or a real camera's controller) with a function `frames.since(seq) -> str`: a JSON
list of `{seq, t_us, ready_us, found, dx_arcsec, dy_arcsec, why}` — the target's
centroid minus the optical axis, azimuth·cos E and elevation, arcseconds, at the
middle of the exposure in mount time (docs/guide-camera.md). The link connects
when first asked and again after a failure; every value read is checked (hostile
until proven otherwise) before the closed loop sees it.
"""

from __future__ import annotations

import json
import math
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any

from astcom_client import AstcomError, Client

from .exceptions import MountUnavailable

__all__ = ["CameraFrame", "CameraLink", "CameraLinkConfig"]

FRAMES_SINCE = "frames.since"
MAX_OFFSET_ARCSEC = 36_000.0  # a centroid farther than 10° is not a guide camera's


@dataclass(frozen=True)
class CameraLinkConfig:
    """Where the guide camera is (`connector` opens an in-memory connection instead)."""

    url: str
    password: str | None = None
    timeout_s: float = 5.0
    connector: Callable[[], Awaitable[Client]] | None = None


@dataclass(frozen=True)
class CameraFrame:
    seq: int
    t_us: int
    ready_us: int
    found: bool
    dx_arcsec: float
    dy_arcsec: float
    why: str


class CameraLink:
    """Frames from a guide camera device, in order, each once."""

    def __init__(self, config: CameraLinkConfig) -> None:
        self.config = config
        self._client: Client | None = None
        self.last_error = ""
        self.bad_frames = 0

    async def _open(self) -> Client:
        if self._client is not None and self._client.connected:
            return self._client
        try:
            if self.config.connector is not None:
                self._client = await self.config.connector()
            else:
                self._client = await Client.connect(self.config.url, password=self.config.password,
                                                    name="virtualstar-server",
                                                    timeout_s=self.config.timeout_s)
        except (OSError, AstcomError, TimeoutError) as exc:
            self.last_error = str(exc) or type(exc).__name__
            raise MountUnavailable(f"the guide camera at {self.config.url} cannot be reached: "
                                   f"{self.last_error}") from None
        return self._client

    async def frames_since(self, seq: int) -> list[CameraFrame]:
        """Frames read out after `seq` (oldest first); MountUnavailable if unreachable."""
        client = await self._open()
        try:
            text = await client.invoke(FRAMES_SINCE, int(seq))
        except (OSError, AstcomError, TimeoutError) as exc:
            self.last_error = str(exc) or type(exc).__name__
            self._client = None
            raise MountUnavailable(f"the guide camera at {self.config.url}: {self.last_error}") \
                from None
        return self._parse(text)

    def _parse(self, text: Any) -> list[CameraFrame]:
        try:
            rows = json.loads(text) if isinstance(text, str) else None
        except ValueError:
            rows = None
        if not isinstance(rows, list):
            self.bad_frames += 1
            return []
        out = []
        for row in rows:
            frame = _frame(row)
            if frame is None:
                self.bad_frames += 1
            else:
                out.append(frame)
        return out

    async def close(self) -> None:
        if self._client is not None:
            await self._client.close()
            self._client = None


def _frame(row: Any) -> CameraFrame | None:
    """One frame from JSON, or None when anything in it is malformed or out of range."""
    if not isinstance(row, dict):
        return None
    try:
        seq, t_us, ready = (int(row[k]) for k in ("seq", "t_us", "ready_us"))
        found = row["found"]
        dx, dy = float(row["dx_arcsec"]), float(row["dy_arcsec"])
        why = str(row.get("why", ""))[:64]
    except (KeyError, TypeError, ValueError, OverflowError):
        return None
    if not isinstance(found, bool) or seq < 0 or not 0 < t_us <= ready:
        return None
    if found and not (math.isfinite(dx) and math.isfinite(dy)
                      and math.hypot(dx, dy) <= MAX_OFFSET_ARCSEC):
        return None
    return CameraFrame(seq, t_us, ready, found, dx, dy, why)
