"""Constants of the pointing model, with where they come from."""

from __future__ import annotations

import math

#: Arcseconds in one radian (exact: 180/π × 3600).
ARCSEC_PER_RAD = 180.0 / math.pi * 3600.0

#: The six purely geometrical alt-az terms of TPOINT (its manual, "Altazimuth" terms);
#: the default model of `pointing-model fit`.
GEOMETRIC_TERMS = ("IA", "IE", "CA", "NPAE", "AN", "AW")

#: Terms every automatic selection starts from (index errors are always present).
AUTO_BASE_TERMS = ("IA", "IE")

#: Terms automatic selection may add. ECEC is left out because in alt-az it is exactly
#: −TF; HACA1/HASA1/HECE1/HESE1 duplicate ACEC/ACES/ECEC/ECES and are left out too.
AUTO_CANDIDATE_TERMS = (
    "CA", "NPAE", "AN", "AW", "TF", "TX",
    "ACEC", "ACES", "ECES",
    "HASA2", "HACA2", "HESA2", "HECA2",
    "HASA3", "HACA3", "HESA3", "HECA3",
    "HECE2", "HESE2",
)

#: Family-wise significance level of one forward-selection step (Bonferroni over the
#: candidates tried in that step).
AUTO_ALPHA = 0.01

#: Automatic selection skips a candidate correlated above this with a chosen term:
#: the fit could not tell the two apart.
AUTO_MAX_CORRELATION = 0.995

#: Correlations above this are reported after a fit (the issue's threshold).
REPORT_CORRELATION = 0.9

#: Encoder → observed iteration stops when a step moves less than this (arcsec).
INVERT_TOLERANCE_ARCSEC = 1e-7

#: ... or after this many steps (a well-behaved model needs 3 to 5).
INVERT_MAX_ITERATIONS = 50
