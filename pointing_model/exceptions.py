"""Exceptions of the pointing model.

    PointingModelError
    ├── DataFormatError(ValueError)      a pointing-run file is malformed (names file, line, expectation)
    ├── UnknownTermError(ValueError)     a term name is neither a TPOINT term nor a valid harmonic
    ├── ModelFileError(ValueError)       a model JSON file is malformed
    ├── FitError(ValueError)             the data cannot determine the requested terms
    └── ConvergenceError(ArithmeticError) encoder → observed iteration did not converge
"""

from __future__ import annotations


class PointingModelError(Exception):
    """Base of every error raised by `pointing_model`."""


class DataFormatError(ValueError, PointingModelError):
    """A pointing-run file does not follow its format.

    Carries `.source` (file name), `.line_no` (1-based, or None) and `.expected`.
    """

    def __init__(self, source: str, line_no: int | None, problem: str, expected: str,
                 line: str | None = None) -> None:
        self.source = source
        self.line_no = line_no
        self.problem = problem
        self.expected = expected
        self.line = line
        where = f"{source}:{line_no}" if line_no is not None else source
        message = f"{where}: {problem}; expected {expected}"
        if line is not None:
            message += f"\n    {line.rstrip()}"
        super().__init__(message)


class UnknownTermError(ValueError, PointingModelError):
    """A term name is not one this package knows; `.name` holds it."""

    def __init__(self, name: str, reason: str) -> None:
        self.name = name
        super().__init__(f"unknown pointing term {name!r}: {reason}")


class ModelFileError(ValueError, PointingModelError):
    """A model JSON document is malformed; `.source` names it."""

    def __init__(self, source: str, problem: str) -> None:
        self.source = source
        super().__init__(f"{source}: {problem}")


class FitError(ValueError, PointingModelError):
    """The observations cannot determine the requested terms."""


class ConvergenceError(ArithmeticError, PointingModelError):
    """The encoder → observed iteration did not converge (e.g. too close to the zenith)."""
