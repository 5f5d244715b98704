"""Exceptions of the astronomy package.

    AstroError
     ├── SiteError(ValueError)             bad site values or site TOML file
     ├── TimeParseError(ValueError)         a UTC string that cannot be read
     ├── CoordinateParseError(ValueError)   an RA/Dec string that cannot be read
     ├── UnknownTarget(KeyError)            a name that is no star, planet or satellite
     ├── SatelliteError(RuntimeError)       SGP4 failed (decayed orbit, bad elements)
     └── UnreachablePath(ValueError)        a path that does not fit the cable wrap / limits

Warnings: EarthOrientationWarning (UserWarning) when IERS predictions or
no IERS values at all are used for a time.
"""


class AstroError(Exception):
    """Base class of every error raised by virtualstar.astro."""


class SiteError(ValueError, AstroError):
    """A site value or site configuration file is invalid."""


class TimeParseError(ValueError, AstroError):
    """A UTC time string cannot be parsed."""


class CoordinateParseError(ValueError, AstroError):
    """An RA/Dec string cannot be parsed."""


class UnknownTarget(KeyError, AstroError):
    """A target name is neither a catalog star, a solar-system body nor a satellite."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ""


class SatelliteError(RuntimeError, AstroError):
    """SGP4 propagation failed; `.code` holds the sgp4 error code."""

    def __init__(self, message: str, code: int = 0) -> None:
        super().__init__(message)
        self.code = code


class UnreachablePath(ValueError, AstroError):
    """A trajectory cannot be followed within the cable wrap or elevation limits."""


class EarthOrientationWarning(UserWarning):
    """IERS Earth orientation for a time comes from predictions or is missing."""
