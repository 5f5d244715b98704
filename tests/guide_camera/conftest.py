"""The guide camera simulator's tests use the VSS tests' independent truth (sky_truth.py)."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "vss"))
