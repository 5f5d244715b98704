"""What the VSS writes in its event log (astcom_client.events), from what it pushes.

The server already pushes events to its clients (`emit(kind, data)`: operations and
their phases, faults, safety actions, modes, mount connections, program progress). The
log keeps them with a level and a one-line message, in mount time, beside the commands
clients sent (with their address and role) and the connections: `describe` is the one
table from a pushed event to a log record.
"""

from __future__ import annotations

from typing import Any

__all__ = ["KEPT_APART", "LOGGED_BY_SENDER", "NOT_LOGGED", "QUIET_COMMANDS", "describe"]

# Kinds any client can cause in numbers keep rings of their own (astcom_client.events):
# however many connections come and go, or passwords are guessed, the operations,
# commands, faults, safety actions and modes in the main ring stay.
KEPT_APART = {"connection": 2000, "auth": 2000}

NOT_LOGGED = frozenset({"heartbeat", "hello"})
# Pushed kinds whose senders log them themselves, with more than the push carries (an
# offset's timing, a closed loop's level): logged once, not again when pushed.
LOGGED_BY_SENDER = frozenset({"offset", "closed_loop"})
# Read-only commands a panel or `vs watch` sends over and over: logging them would drown
# the log (a refused one is still logged).
QUIET_COMMANDS = frozenset({"ping", "status", "errors", "wait", "program", "log"})

# pushed kind -> (level, logged kind)
_TABLE: dict[str, tuple[str, str]] = {
    "operation": ("info", "phase"),
    "resumed": ("info", "operation"),
    "slew_done": ("info", "operation"),
    "fault": ("error", "fault"),
    "safety": ("warning", "safety"),
    "safety_override": ("warning", "safety"),
    "mode": ("info", "mode"),
    "mount_connected": ("info", "connection"),
    "mount_disconnected": ("warning", "connection"),
    "program": ("info", "program"),
}


def _message(kind: str, data: dict[str, Any]) -> str:
    if kind == "operation":
        return (f"{data.get('kind', 'operation')} {data.get('id', '')}: {data.get('phase', '')}"
                + (f" ({data['info']})" if data.get("info") else ""))
    if kind == "fault":
        return f"mount fault: {data.get('faults', '')}"
    if kind == "safety":
        return f"safety: {data.get('reason', '')} → {data.get('action', '')}"
    if kind == "mode":
        return f"mode {data.get('mode')}"
    if kind == "slew_done":
        return f"slew {data.get('id', '')} landed"
    return kind.replace("_", " ") + (f": {data['id']}" if "id" in data else "")


def describe(kind: str, data: dict[str, Any]) -> tuple[str, str, str] | None:
    """Return (level, logged kind, message) of a pushed event; None when it is not logged."""
    if kind in NOT_LOGGED or kind in LOGGED_BY_SENDER:
        return None
    level, logged = _TABLE.get(kind, ("info", kind))
    return level, logged, _message(kind, data)
