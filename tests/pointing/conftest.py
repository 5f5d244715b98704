"""Fixtures of the pointing-model tests: the AuxTel reference run, read in place."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[2]
AUXTEL_ENV = "VIRTUALSTAR_AUXTEL_DAT"
AUXTEL_DEFAULT = REPO_ROOT / ".." / "shared" / "data" / "pointing" / "auxtel_20220406.dat"


@pytest.fixture(scope="session")
def auxtel_path() -> Path:
    """Path of the AuxTel 2022-04-06 TPOINT run ($VIRTUALSTAR_AUXTEL_DAT overrides); skip if absent."""
    path = Path(os.environ.get(AUXTEL_ENV, AUXTEL_DEFAULT))
    if not path.is_file():
        pytest.skip(f"AuxTel reference run not found at {path} (set {AUXTEL_ENV} to its path)")
    return path


@pytest.fixture(scope="session")
def auxtel_fauto_path(auxtel_path) -> Path:
    """TPOINT's own automatic fit of the same run (`OUTMOD` layout), beside it; skip if absent."""
    path = auxtel_path.with_name("auxtel_20220406_fauto.mod")
    if not path.is_file():
        pytest.skip(f"TPOINT's model of the AuxTel run not found at {path}")
    return path
