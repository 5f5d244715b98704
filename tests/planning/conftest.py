"""The planning tests run plans on the VSS rig of tests/vss (emulator + server in lockstep)."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "vss"))
