"""Errors of the panel server.

    PanelError
    ├── BundleMissing(FileNotFoundError)   the built front end is not there: build it
    └── CannotListen(OSError)              the address or port cannot be bound
"""

from __future__ import annotations

__all__ = ["BundleMissing", "CannotListen", "PanelError"]


class PanelError(Exception):
    """Base of every panel error."""


class BundleMissing(FileNotFoundError, PanelError):
    """The built bundle (index.html) is missing from the static folder."""

    def __init__(self, static_dir: str) -> None:
        super().__init__(
            f"the panel is not built: {static_dir}/index.html is missing; "
            "run `bash setup/30-panel.sh` (or `make`), which runs `npm ci && npm run build` in panel/"
        )
        self.static_dir = static_dir


class CannotListen(OSError, PanelError):
    """The HTTP server cannot bind its address."""

    def __init__(self, host: str, port: int, reason: str) -> None:
        super().__init__(f"cannot listen on {host}:{port}: {reason} (choose another --port or --host)")
        self.host = host
        self.port = port
