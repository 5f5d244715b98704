"""Configure an emulator: defaults in one place, a TOML file on top, CLI options last.

A config file is TOML. Tables other than ``[emulator]`` and ``[geometry]`` name
parameters by their registered dotted names, e.g.::

    [emulator]
    az_deg = 0.0            # start position
    el_deg = 20.0
    traj_capacity = 4096    # points
    seeing_arcsec = 0.3

    [axis.az]
    kp = 35.0               # axis.az.kp
    [time]
    drift_ppm = 1.5

    [geometry]              # TPOINT terms in arcsec (else --geometry FILE or --seed N)
    IA = 120.0
"""

from __future__ import annotations

import difflib
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from mount_emulator import layout as L
from mount_emulator.exceptions import ConfigError
from mount_emulator.geometry import DEFAULT_SEEING_ARCSEC, Geometry
from mount_emulator.model import DEFAULT_TRAJ_CAPACITY

__all__ = ["EmulatorConfig", "load_config_file"]

DEFAULT_START_EL_DEG = 20.0


@dataclass
class EmulatorConfig:
    """Everything an emulator needs; keyword defaults are the documented ones.

    ``speed``: 1.0 real time, X for X times real time, 0 for as fast as possible.
    ``start_us``: mount and true time at start (µs since 1970 UTC); None = now.
    ``passwords``: role → password for the Endpoint, None = no authentication.
    """

    speed: float = 1.0
    start_us: int | None = None
    params: dict[str, float] = field(default_factory=dict)
    geometry: Geometry = field(default_factory=Geometry)
    seeing_arcsec: float = DEFAULT_SEEING_ARCSEC
    guide_seed: int | None = None
    az_deg: float = 0.0
    el_deg: float = DEFAULT_START_EL_DEG
    traj_capacity: int = DEFAULT_TRAJ_CAPACITY
    passwords: dict[str, str] | None = None
    block_s: float = 0.002  # real-time loop wake-up period
    stream_flush_s: float = 0.02  # mount time of samples per stream packet (lockstep: longer)


def _flatten(data: dict, prefix: str = "") -> dict[str, object]:
    out: dict[str, object] = {}
    for key, value in data.items():
        name = f"{prefix}.{key}" if prefix else key
        if isinstance(value, dict):
            out.update(_flatten(value, name))
        else:
            out[name] = value
    return out


def load_config_file(path: str | Path, config: EmulatorConfig | None = None) -> EmulatorConfig:
    """Read a TOML config file onto ``config`` (or the defaults); raise ConfigError on any mistake."""
    path = Path(path)
    config = config or EmulatorConfig()
    try:
        data = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise ConfigError(f"config file {path} does not exist") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"config file {path} is not valid TOML: {exc}") from None
    emulator = data.pop("emulator", {})
    if "geometry" in data:
        config.geometry = Geometry.from_mapping(data.pop("geometry"), where=f"{path} [geometry]")
    known = {"az_deg": float, "el_deg": float, "traj_capacity": int, "seeing_arcsec": float}
    for key, value in emulator.items():
        if key not in known:
            raise ConfigError(f"{path} [emulator]: unknown key {key!r}; expected one of "
                              f"{', '.join(known)}")
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"{path} [emulator]: {key} must be a number, got {value!r}")
        setattr(config, key, known[key](value))
    if config.traj_capacity < 16:
        raise ConfigError(f"{path} [emulator]: traj_capacity must be at least 16, got {config.traj_capacity}")
    for name, value in _flatten(data).items():
        if name not in L.PARAM_INDEX:
            close = difflib.get_close_matches(name, L.PARAM_INDEX, n=3)
            hint = f"; did you mean {', '.join(close)}?" if close else ""
            raise ConfigError(f"{path}: unknown parameter {name!r}{hint}")
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
            raise ConfigError(f"{path}: {name} must be a finite number, got {value!r}")
        config.params[name] = float(value)
    return config
