"""The C library's own small formatter (ad_snprintf, used instead of the C library's float
printf so the firmware fits) against the host C library's snprintf on 1.4 million cases:
exact on plain numbers, within one unit of the last digit elsewhere
(astcom_device/tests/fmt_check.c, built with ASan and UBSan)."""

import subprocess

import pytest
from device_impls import DEVICE_DIR, c_toolchain_missing


def test_the_device_formats_numbers_as_the_c_library_does():
    if (missing := c_toolchain_missing()) is not None:
        pytest.fail(f"the C device cannot be built: {missing}")
    done = subprocess.run(["make", "-s", "-C", str(DEVICE_DIR), "fmt-check"],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    assert "mismatches 0" in done.stdout
