"""The Robot Supervisor Panel: a browser front end (built from panel/) served over HTTP."""

from virtualstar.panel.exceptions import BundleMissing, CannotListen, PanelError
from virtualstar.panel.server import (
    DEFAULT_ENDPOINT,
    DEFAULT_HOST,
    DEFAULT_PORT,
    DEFAULT_VSS,
    STATIC_DIR,
    PanelConfig,
    PanelServer,
)

__all__ = ["DEFAULT_ENDPOINT", "DEFAULT_HOST", "DEFAULT_PORT", "DEFAULT_VSS", "STATIC_DIR", "BundleMissing",
           "CannotListen", "PanelConfig", "PanelError", "PanelServer"]
