"""An observing program: the targets of a night and what each needs, read from TOML.

A program file (commented example: catalogs/data/program-example.toml) has a
`[defaults]` table and one `[[target]]` table per target. A target is exactly one of:

* ``star = "Vega"`` (a bundled bright star, or a planet / the Moon by name),
* ``radec = "18h36m56.3s +38d47m01s"`` (ICRS),
* ``tle_file = "stations.tle"`` with ``sat = "ISS"`` (a satellite; the path is relative
  to the program file).

and may set, overriding `[defaults]`:

| key | meaning |
|---|---|
| `name` | how the plan calls it (default: the star / satellite name) |
| `priority` | a number > 0: higher first; a block counts priority × hours |
| `duration_s`, or `exposures` × `exposure_s` (+ `overhead_s`) | time on target (sidereal) |
| `repeats`, `cadence_s` | how many blocks, at least how far apart (start to start) |
| `min_el_deg` | lowest elevation (the site's horizon profile applies too) |
| `az_windows_deg` | `[[from, to], ...]` azimuth ranges allowed (through north if from > to) |
| `sun_max_el_deg` | the Sun below this: -6 civil, -12 nautical, -18 astronomical dusk |
| `moon_min_sep_deg` | at least this far from the Moon |
| `window` | `["start UTC", "end UTC"]`: only within these times |
| `sunlit_while_dark` | satellites: only while the satellite is sunlit and the site dark |
| `closed_loop` | `true`: track guided by the server's guide camera (`vs server --camera`) |

Errors name the file, the target (its index and name) and the key, with what is expected.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from virtualstar.astro import UtcTimes

from .exceptions import ProgramError

__all__ = ["Program", "ProgramTarget", "load_program"]

_DEFAULTS = {"priority": 1.0, "duration_s": 600.0, "repeats": 1, "cadence_s": 0.0,
             "min_el_deg": 30.0, "sun_max_el_deg": -12.0, "moon_min_sep_deg": 0.0,
             "overhead_s": 0.0}
_TARGET_KEYS = {"name", "star", "radec", "tle_file", "sat", "priority", "duration_s",
                "exposures", "exposure_s", "overhead_s", "repeats", "cadence_s", "min_el_deg",
                "az_windows_deg", "sun_max_el_deg", "moon_min_sep_deg", "window",
                "sunlit_while_dark", "closed_loop"}


@dataclass(frozen=True)
class ProgramTarget:
    """One target of a program with its needs (degrees, seconds; UTC µs for the window)."""

    name: str
    kind: str  # "star" (a catalog star or a body), "radec" or "satellite"
    spec: str  # the star/body name, the RA/Dec text, or the satellite's name in its TLE file
    priority: float
    duration_s: float
    repeats: int
    cadence_s: float
    min_el_deg: float
    sun_max_el_deg: float
    moon_min_sep_deg: float
    az_windows_deg: tuple[tuple[float, float], ...] = ()
    window_us: tuple[int, int] | None = None
    tle_file: Path | None = None
    tle_text: str = ""  # the TLE file's text, read once: a plan carries it to the server
    sunlit_while_dark: bool = False
    closed_loop: bool = False  # guided by the server's guide camera (docs/vss.md)
    index: int = 0  # its place in the file (ties are broken by it: a plan is deterministic)

    def as_dict(self) -> dict[str, Any]:
        d = {f: getattr(self, f) for f in self.__dataclass_fields__}
        d["tle_file"] = None if self.tle_file is None else str(self.tle_file)
        d["az_windows_deg"] = [list(w) for w in self.az_windows_deg]
        d["window_us"] = None if self.window_us is None else list(self.window_us)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ProgramTarget:
        """Rebuild a target from `as_dict` (as carried in a plan); raise ProgramError."""
        if not isinstance(d, dict):
            raise ProgramError(f"a plan's program target is {type(d).__name__}, not a table: "
                               "write the plan again with vs plan")
        try:
            fields = {k: d[k] for k in cls.__dataclass_fields__ if k in d}
            fields["tle_file"] = None if d.get("tle_file") is None else Path(str(d["tle_file"]))
            fields["az_windows_deg"] = tuple(tuple(float(x) for x in w)
                                             for w in d.get("az_windows_deg", ()))
            window = d.get("window_us")
            fields["window_us"] = None if window is None else (int(window[0]), int(window[1]))
            target = cls(**fields)
            target._check_carried()
            return target
        except (KeyError, TypeError, ValueError, IndexError, OverflowError) as exc:
            raise ProgramError(f"a plan's program target {str(d.get('name', '?'))[:40]!r} is "
                               f"incomplete or malformed ({exc}): write the plan again with "
                               "vs plan") from None

    def _check_carried(self) -> None:
        """The ranges `load_program` enforces, again for a target a plan carried (a client's
        input): ValueError/TypeError naming the field."""
        for name in ("name", "kind", "spec", "tle_text"):
            if not isinstance(getattr(self, name), str):
                raise TypeError(f"{name}: text expected")
        if self.kind not in ("star", "radec", "satellite"):
            raise ValueError(f"kind {self.kind[:20]!r}: expected star, radec or satellite")
        for name, lo, hi in (("priority", 1e-6, 1e6), ("duration_s", 1e-3, 1e7),
                             ("cadence_s", 0.0, 86400.0 * 7), ("min_el_deg", -5.0, 89.0),
                             ("sun_max_el_deg", -90.0, 90.0), ("moon_min_sep_deg", 0.0, 180.0)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not lo <= v <= hi:
                raise ValueError(f"{name} = {str(v)[:40]!r}: expected a number in {lo:g}..{hi:g}")
        for name, lo, hi in (("repeats", 1, 1000), ("index", 0, 10**6)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
                raise ValueError(f"{name} = {str(v)[:40]!r}: expected a whole number {lo}..{hi}")
        if not all(0.0 <= x <= 360.0 for w in self.az_windows_deg for x in w) or not all(
                len(w) == 2 for w in self.az_windows_deg):
            raise ValueError("az_windows_deg: expected [from, to] pairs in degrees 0..360")
        if self.window_us is not None and not 0 <= self.window_us[0] < self.window_us[1] < 2**62:
            raise ValueError("window_us: expected start < end, integer µs since 1970")
        for name in ("sunlit_while_dark", "closed_loop"):
            if not isinstance(getattr(self, name), bool):
                raise TypeError(f"{name}: true or false expected")

    @property
    def is_satellite(self) -> bool:
        return self.kind == "satellite"

    def az_allowed(self, az_deg):
        """Return a mask of the azimuths (deg, any array) inside the allowed windows."""
        import numpy as np

        az = np.mod(np.asarray(az_deg, float), 360.0)
        if not self.az_windows_deg:
            return np.ones(az.shape, bool)
        ok = np.zeros(az.shape, bool)
        for lo, hi in self.az_windows_deg:
            ok |= (az >= lo) & (az <= hi) if lo <= hi else (az >= lo) | (az <= hi)
        return ok


@dataclass(frozen=True)
class Program:
    """A program file's targets, in file order."""

    name: str
    targets: tuple[ProgramTarget, ...] = field(default_factory=tuple)
    source: str = ""

    def as_dict(self) -> dict[str, Any]:
        return {"name": self.name, "source": self.source,
                "targets": [t.as_dict() for t in self.targets]}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Program:
        targets = d.get("targets") if isinstance(d, dict) else None
        if not isinstance(targets, list):
            raise ProgramError("a plan without its program (program_spec.targets): write the "
                               "plan again with vs plan")
        return cls(str(d.get("name", "")), tuple(ProgramTarget.from_dict(t) for t in targets),
                   str(d.get("source", "")))


def load_program(path: str | Path) -> Program:
    """Read and check a program file; raise ProgramError saying where and what is expected."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ProgramError(f"cannot read program {path}: {exc.strerror or exc}") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ProgramError(f"{path}: not valid TOML: {exc}") from None
    unknown = sorted(set(data) - {"program", "defaults", "target"})
    if unknown:
        raise ProgramError(f"{path}: unknown tables {unknown}; expected [program], [defaults] "
                           "and [[target]]")
    defaults = dict(_DEFAULTS)
    given = data.get("defaults", {})
    bad = sorted(set(given) - _TARGET_KEYS)
    if bad:
        raise ProgramError(f"{path} [defaults]: unknown keys {bad}; valid: {sorted(_TARGET_KEYS)}")
    defaults.update(given)
    tables = data.get("target", [])
    if not isinstance(tables, list) or not tables:
        raise ProgramError(f"{path}: no [[target]] tables; a program needs at least one target")
    targets = tuple(_target(path, i, {**defaults, **t}) for i, t in enumerate(tables))
    names = [t.name for t in targets]
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise ProgramError(f"{path}: two targets are called {dupes}: give each a distinct name")
    program = data.get("program", {})
    return Program(str(program.get("name", path.stem)), targets, str(path))


def _target(path: Path, index: int, t: dict[str, Any]) -> ProgramTarget:
    where = f"{path} [[target]] #{index + 1}" + (f" ({t['name']})" if "name" in t else "")
    bad = sorted(set(t) - _TARGET_KEYS)
    if bad:
        raise ProgramError(f"{where}: unknown keys {bad}; valid: {sorted(_TARGET_KEYS)}")
    kinds = [k for k in ("star", "radec", "tle_file") if k in t]
    if len(kinds) != 1:
        raise ProgramError(f"{where}: give exactly one of star = \"NAME\", radec = \"RA DEC\" or "
                           f"tle_file = \"FILE\" (+ sat = \"NAME\"); got {kinds or 'none'}")
    kind = kinds[0]

    def number(key: str, lo: float, hi: float) -> float:
        value = t[key]
        if isinstance(value, bool) or not isinstance(value, int | float) \
                or not math.isfinite(value) or not lo <= value <= hi:
            raise ProgramError(f"{where}: {key} = {value!r}: expected a number in {lo:g}..{hi:g}")
        return float(value)

    duration = number("duration_s", 1.0, 86400.0)
    if "exposures" in t or "exposure_s" in t:
        if "exposures" not in t or "exposure_s" not in t:
            raise ProgramError(f"{where}: exposures and exposure_s go together")
        duration = (number("exposures", 1, 100000) * number("exposure_s", 0.001, 86400.0)
                    + number("overhead_s", 0.0, 86400.0))
    spec = str(t[kind]) if kind != "tle_file" else str(t.get("sat", ""))
    tle_file, tle_text = None, ""
    if kind == "tle_file":
        from catalogs import ElementFileError, read_element_text

        tle_file = (path.parent / str(t["tle_file"])).resolve()
        if not spec:
            raise ProgramError(f"{where}: a tle_file needs sat = \"NAME\" (the satellite in it)")
        try:
            tle_text = read_element_text(tle_file)
        except ElementFileError as exc:
            raise ProgramError(f"{where}: tle_file {t['tle_file']!r}: {exc}") from None
    elif kind == "radec":
        from virtualstar.astro import AstroError, parse_radec

        try:
            parse_radec(spec)
        except AstroError as exc:
            raise ProgramError(f"{where}: {exc}") from None
    windows = []
    for w in t.get("az_windows_deg", []):
        if not (isinstance(w, list) and len(w) == 2
                and all(isinstance(x, int | float) and 0 <= x <= 360 for x in w)):
            raise ProgramError(f"{where}: az_windows_deg entry {w!r}: expected [from, to] in "
                               "degrees 0..360 (through north when from > to)")
        windows.append((float(w[0]), float(w[1])))
    window_us = None
    if "window" in t:
        w = t["window"]
        if not (isinstance(w, list) and len(w) == 2):
            raise ProgramError(f"{where}: window = {w!r}: expected [\"start UTC\", \"end UTC\"]")
        try:
            a, b = (int(x) for x in UtcTimes.from_iso([str(w[0]), str(w[1])]).to_unix_us())
        except Exception as exc:
            raise ProgramError(f"{where}: window: {exc}") from None
        if b <= a:
            raise ProgramError(f"{where}: window ends before it starts")
        window_us = (a, b)
    closed_loop = t.get("closed_loop", False)
    if not isinstance(closed_loop, bool):
        raise ProgramError(f"{where}: closed_loop = {closed_loop!r}: expected true or false")
    repeats = t["repeats"]
    if isinstance(repeats, bool) or not isinstance(repeats, int) or not 1 <= repeats <= 1000:
        raise ProgramError(f"{where}: repeats = {repeats!r}: expected a whole number 1..1000")
    target = ProgramTarget(
        name=str(t.get("name") or spec), kind="satellite" if kind == "tle_file" else kind,
        spec=spec, priority=number("priority", 1e-6, 1e6), duration_s=duration,
        repeats=int(repeats), cadence_s=number("cadence_s", 0.0, 86400.0 * 7),
        min_el_deg=number("min_el_deg", -5.0, 89.0),
        sun_max_el_deg=number("sun_max_el_deg", -90.0, 90.0),
        moon_min_sep_deg=number("moon_min_sep_deg", 0.0, 180.0),
        az_windows_deg=tuple(windows), window_us=window_us, tle_file=tle_file, tle_text=tle_text,
        sunlit_while_dark=bool(t.get("sunlit_while_dark", False)), closed_loop=closed_loop,
        index=index)
    return replace(target, name=target.name.strip() or f"target {index + 1}")
