"""Serve ASCOM's alpaca-simulators with uvicorn, its camera's image library loaded only if used.

Usage: alpaca_sim_serve.py APP [uvicorn's options]   (as ``python -m uvicorn APP ...``)

The simulator's app imports every device's API at start, and its camera's imports
``cabaret`` (astropy, matplotlib: about two thirds of the simulator's start-up CPU, ~1 s
on a quiet host, for each of the backend scenario's simulator starts). The backend tests
drive its telescope only. ``cabaret`` is registered here with the standard library's
`importlib.util.LazyLoader`: the camera module's ``import cabaret`` binds it, and the
library really loads on first use (a camera image). Nothing of the simulator changes.
"""

from __future__ import annotations

import importlib.abc
import importlib.util
import sys


class LazyFinder(importlib.abc.MetaPathFinder):
    """Finds the modules named in `names` as usual, with a `LazyLoader` in front: the
    module is bound at its ``import`` and executed at its first attribute access."""

    def __init__(self, names: set[str]) -> None:
        self.names = names

    def find_spec(self, name, path, target=None):
        if name not in self.names:
            return None
        self.names = self.names - {name}  # the real finder, not this one, from now on
        spec = importlib.util.find_spec(name)
        if spec is None or spec.loader is None:
            return None
        spec.loader = importlib.util.LazyLoader(spec.loader)
        return spec


if __name__ == "__main__":
    sys.meta_path.insert(0, LazyFinder({"cabaret"}))
    import uvicorn

    sys.argv[0] = "uvicorn"
    uvicorn.main()
