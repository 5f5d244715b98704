"""Pair each VSS role with a mount's signal or function name, read from a JSON file.

A role is what the server needs ("azimuth encoder position", "push trajectory
points"); the mapping names the variable of a particular controller that plays
it. The bundled file `virtualstar/data/emulator-mapping.json` maps the roles
onto the mount emulator; another controller needs only another file. The file
layout and the signature each function role must have are in docs/vss.md.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from .exceptions import MappingError

__all__ = [
    "DEFAULT_MAPPING_NAME",
    "FUNCTION_ROLES",
    "OPTIONAL_FUNCTION_ROLES",
    "OPTIONAL_SIGNAL_ROLES",
    "REQUIRED_SIGNAL_ROLES",
    "STATE_NAMES",
    "RoleMapping",
    "load_mapping",
]

DEFAULT_MAPPING_NAME = "data/emulator-mapping.json"

REQUIRED_SIGNAL_ROLES = (
    "az_position", "el_position", "az_state", "el_state", "az_faults", "el_faults",
    "mount_state", "mount_time", "free_points", "az_error", "el_error",
)
OPTIONAL_SIGNAL_ROLES = (
    "az_fault_text", "el_fault_text", "utc_truth", "pps_error", "sync_count",
    "buffered_points", "underruns", "late_points",
    "az_slew_rate_limit", "el_slew_rate_limit", "az_slew_accel_limit", "el_slew_accel_limit",
    "az_track_rate_limit", "el_track_rate_limit", "az_min", "az_max", "el_min", "el_max",
    "replace_min_lead",
)
FUNCTION_ROLES = (
    "power_on", "power_off", "stop", "slew", "traj_init", "traj_start", "traj_reset",
    "traj_push", "time_sync", "reset_faults",
)
# A mount without a guide camera leaves `guide_measure` out; `pointing_sample` then says so.
# A controller whose buffer only appends leaves `traj_replace` out: corrections then start
# after the points already buffered (the VSS says so in `status`, "corrections").
OPTIONAL_FUNCTION_ROLES = ("guide_measure", "traj_replace")
STATE_NAMES = ("off", "holding", "slewing", "tracking", "manual", "stopping", "fault")


@dataclass(frozen=True)
class RoleMapping:
    """Role → mount name for signals and functions, state codes, park position (degrees)."""

    signals: dict[str, str]
    functions: dict[str, str]
    state_codes: dict[str, int]
    park_az_deg: float = 0.0
    park_el_deg: float = 85.0
    source: str = "<mapping>"
    extra: dict[str, Any] = field(default_factory=dict)

    def signal(self, role: str) -> str:
        """Return the mount's name for a signal role; raise MappingError if unmapped."""
        try:
            return self.signals[role]
        except KeyError:
            raise MappingError(f"{self.source}: no signal mapped for role {role!r}") from None

    def has(self, role: str) -> bool:
        return role in self.signals

    def function(self, role: str) -> str:
        """Return the mount's name for a function role; raise MappingError if unmapped."""
        try:
            return self.functions[role]
        except KeyError:
            raise MappingError(f"{self.source}: no function mapped for role {role!r}") from None

    def has_function(self, role: str) -> bool:
        return role in self.functions

    def state_name(self, code: int) -> str:
        """Return the state name of a mount state code ("unknown(7)" if unmapped)."""
        for name, value in self.state_codes.items():
            if value == code:
                return name
        return f"unknown({code})"

    @classmethod
    def from_dict(cls, doc: Any, source: str = "<mapping>") -> RoleMapping:
        """Build and check a mapping from parsed JSON; raise MappingError naming the problem."""
        if not isinstance(doc, dict):
            raise MappingError(f"{source}: expected a JSON object with 'signals', 'functions' "
                               "and 'state_codes'")
        signals = _names(doc, "signals", source)
        functions = _names(doc, "functions", source)
        missing = [r for r in REQUIRED_SIGNAL_ROLES if r not in signals]
        missing += [r for r in FUNCTION_ROLES if r not in functions]
        if missing:
            raise MappingError(f"{source}: roles missing: {', '.join(missing)}")
        unknown = sorted(set(signals) - set(REQUIRED_SIGNAL_ROLES) - set(OPTIONAL_SIGNAL_ROLES))
        unknown += sorted(set(functions) - set(FUNCTION_ROLES) - set(OPTIONAL_FUNCTION_ROLES))
        if unknown:
            raise MappingError(f"{source}: unknown roles {', '.join(unknown)}; valid signal roles: "
                               f"{', '.join(REQUIRED_SIGNAL_ROLES + OPTIONAL_SIGNAL_ROLES)}; "
                               f"function roles: {', '.join(FUNCTION_ROLES + OPTIONAL_FUNCTION_ROLES)}")
        codes = doc.get("state_codes")
        if not isinstance(codes, dict) or any(n not in codes for n in STATE_NAMES):
            raise MappingError(f"{source}: 'state_codes' must give an integer for each of "
                               f"{', '.join(STATE_NAMES)}")
        if not all(isinstance(v, int) and not isinstance(v, bool) for v in codes.values()):
            raise MappingError(f"{source}: every state code must be an integer")
        park = doc.get("park", {})
        try:
            park_az, park_el = float(park.get("az_deg", 0.0)), float(park.get("el_deg", 85.0))
        except (AttributeError, TypeError, ValueError):
            raise MappingError(f"{source}: 'park' must be {{\"az_deg\": number, "
                               "\"el_deg\": number}") from None
        return cls(signals, functions, {k: int(v) for k, v in codes.items()}, park_az, park_el,
                   source)


def _names(doc: dict, key: str, source: str) -> dict[str, str]:
    table = doc.get(key)
    if not isinstance(table, dict) or not all(
            isinstance(k, str) and isinstance(v, str) and v for k, v in table.items()):
        raise MappingError(f"{source}: {key!r} must be an object of role -> mount name (text)")
    return dict(table)


def load_mapping(path: str | Path | None = None) -> RoleMapping:
    """Load a mapping file (default: the bundled emulator mapping); raise MappingError."""
    if path is None:
        text = resources.files("virtualstar").joinpath(DEFAULT_MAPPING_NAME).read_text("utf-8")
        source = "default emulator mapping"
    else:
        source = str(path)
        try:
            text = Path(path).read_text("utf-8")
        except OSError as exc:
            raise MappingError(f"cannot read mapping file {source}: {exc.strerror}") from None
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise MappingError(f"{source}: not valid JSON: {exc}") from None
    return RoleMapping.from_dict(doc, source)
