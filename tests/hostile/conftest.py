"""The hostile suite: real `vs server` processes on loopback, attacked as a stranger would."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
sys.path.insert(0, str(Path(__file__).parents[1] / "vss"))  # the lockstep rig (vss_rig)
