"""The project installs as one distribution with the five packages importable."""

import importlib

import pytest


@pytest.mark.parametrize(
    "package", ["astcom_client", "mount_emulator", "virtualstar", "pointing_model", "catalogs"]
)
def test_package_imports(package: str) -> None:
    module = importlib.import_module(package)
    assert module.__doc__
