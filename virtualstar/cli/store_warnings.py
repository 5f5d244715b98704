"""Damaged-file warnings of the stores as one plain stderr line each (`vs data`, `vs log`).

Kept apart from the commands so that importing it costs nothing: `--help` stays fast.
"""

from __future__ import annotations

import functools
import warnings

import typer

__all__ = ["reports_damage"]


def reports_damage(prefix: str):
    """Decorate a command so that DamagedFileWarnings come out as one stderr line each
    (`<prefix>: warning: <file> is damaged (...): ...`), never as Python's warning text."""
    def wrap(command):
        @functools.wraps(command)
        def run(*args, **kwargs):
            from virtualstar.recorder.damage import DamagedFileWarning

            with warnings.catch_warnings():
                warnings.simplefilter("always", DamagedFileWarning)
                original = warnings.showwarning

                def show(message, category, filename, lineno, file=None, line=None):
                    if issubclass(category, DamagedFileWarning):
                        typer.echo(f"{prefix}: warning: {message}", err=True)
                    else:
                        original(message, category, filename, lineno, file, line)

                warnings.showwarning = show
                return command(*args, **kwargs)
        return run
    return wrap
