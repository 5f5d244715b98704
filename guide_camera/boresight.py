"""Where the optical axis truly points: the encoders through the mount's hidden geometry.

The emulator publishes its true geometry (`truth.geometry_arcsec`: the TPOINT
alt-az terms IA, IE, AN, AW, NPAE, CA, TF, arcseconds) for truth devices like this
camera. With TPOINT's convention, observed − encoder = Δ(observed):

    ΔA = −IA − CA·secE − NPAE·tanE − AN·sinA·tanE − AW·cosA·tanE
    ΔE = +IE − AN·cosA + AW·sinA − TF·cosE

(docs/mount-emulator.md, "Hidden geometry"). The camera finds the observed place on
the axis by fixed-point iteration from the encoder readings; it does not import the
emulator (it sits beside it, as a separate device would), and a test checks the two
agree.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["TERMS", "axis_place"]

TERMS = ("ia", "ie", "an", "aw", "npae", "ca", "tf")
ARCSEC = math.pi / 180.0 / 3600.0


def _delta(terms: np.ndarray, az: np.ndarray, el: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    ia, ie, an, aw, npae, ca, tf = (float(x) for x in terms)
    sa, ca_ = np.sin(az), np.cos(az)
    tan_e, cos_e = np.tan(el), np.cos(el)
    d_az = -ia - ca / cos_e - npae * tan_e - an * sa * tan_e - aw * ca_ * tan_e
    d_el = ie - an * ca_ + aw * sa - tf * cos_e
    return d_az * ARCSEC, d_el * ARCSEC


def axis_place(terms_arcsec, enc_az_rad, enc_el_rad) -> tuple[np.ndarray, np.ndarray]:
    """Return the observed (az, el) radians the optical axis points to, for encoder readings."""
    terms = np.asarray(terms_arcsec, float)
    az0 = np.asarray(enc_az_rad, float)
    el0 = np.asarray(enc_el_rad, float)
    az, el = az0, el0
    for _ in range(5):  # Δ varies slowly over the sky: converges to < 1e-9″
        d_az, d_el = _delta(terms, az, el)
        az, el = az0 + d_az, el0 + d_el
    return az, el
