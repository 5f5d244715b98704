"""The VirtualStar Server (VSS): drive a mount over ASTCom, serve clients over WebSocket/JSON.

Library use::

    from virtualstar.server import build_server
    server = build_server(mount_url="ws://127.0.0.1:8765", password=None, site=load_site())
    url = await server.start("ws://127.0.0.1:8740")
    ...
    await server.close()

Parts: `MountLink` (serialised, reconnecting ASTCom client spoken in roles from a
`RoleMapping`), `Feeder` (keeps the trajectory buffer filled), `TimeSync`,
`TrackingErrorHistory`, `Telescope` (operations, status, faults) and `VssServer`
(the API, docs/vss-api.md).
"""

from .access import AccessConfig
from .assembly import build_server
from .commands import COMMANDS
from .exceptions import (
    BadRequest,
    MappingError,
    MountFault,
    MountRejected,
    MountUnavailable,
    NotActive,
    OperationAborted,
    TargetUnreachable,
    UnknownCommand,
    VssError,
)
from .feeder import Feeder, FeederConfig
from .mapping import RoleMapping, load_mapping
from .mount_link import LinkConfig, MountLink
from .protocol import ErrorReply, Event, Reply, Request
from .server import DEFAULT_PORT, VssServer
from .telescope import Telescope, TelescopeConfig
from .timesync import TimeSync
from .tracking_errors import ErrorStats, TrackingErrorHistory
from .trajectories import Points, RampIn, TablePath, TargetPath, plan_satellite_pass

__all__ = [
    "COMMANDS",
    "AccessConfig",
    "DEFAULT_PORT",
    "BadRequest",
    "ErrorReply",
    "ErrorStats",
    "Event",
    "Feeder",
    "FeederConfig",
    "LinkConfig",
    "MappingError",
    "MountFault",
    "MountLink",
    "MountRejected",
    "MountUnavailable",
    "NotActive",
    "OperationAborted",
    "Points",
    "RampIn",
    "Reply",
    "Request",
    "RoleMapping",
    "TablePath",
    "TargetPath",
    "TargetUnreachable",
    "Telescope",
    "TelescopeConfig",
    "TimeSync",
    "TrackingErrorHistory",
    "UnknownCommand",
    "VssError",
    "VssServer",
    "build_server",
    "load_mapping",
    "plan_satellite_pass",
]
