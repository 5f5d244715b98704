"""Errors of observation planning and running.

::

    PlanningError (RuntimeError)
    ├── ProgramError (ValueError)   the program file is wrong: where, and what is expected
    └── PlanFileError (ValueError)  a plan file (vs plan --json) cannot be read back
"""

from __future__ import annotations

__all__ = ["PlanFileError", "PlanningError", "ProgramError"]


class PlanningError(RuntimeError):
    """Base of every planning error."""


class ProgramError(ValueError, PlanningError):
    """A program file is wrong; the message names the file, the target and the key."""


class PlanFileError(ValueError, PlanningError):
    """A plan file cannot be read back (not JSON, or not what vs plan writes)."""
