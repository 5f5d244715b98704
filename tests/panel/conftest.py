"""The telescope-level panel tests run `vs server` as tests/vss does (vss_rig.vs_server_process)."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "vss"))
