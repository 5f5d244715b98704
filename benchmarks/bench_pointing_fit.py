"""Benchmark: fit 1000 observations with 20 TPOINT terms (goal ≤ 0.5 s).

Prints our complete fit (design matrix, scipy lstsq, σ, correlations, condition number,
leave-one-out RMS) beside two references measured in the same run on the same data:
numpy.linalg.lstsq on the same design matrix, and building that matrix alone.

    .venv/bin/python benchmarks/bench_pointing_fit.py
"""

from __future__ import annotations

import timeit

import numpy as np

from pointing_model import design_matrix, fit_run, model_from_values, select_terms, simulate_run

N_OBS = 1000
TERMS = ("IA", "IE", "CA", "NPAE", "AN", "AW", "TF", "TX", "ACEC", "ACES", "ECES",
         "HASA2", "HACA2", "HESA2", "HECA2", "HASA3", "HACA3", "HESA3", "HECA3", "HSCA5CE8")
GOAL_S = 0.5


def best_of(fn, repeat: int = 7, number: int = 5) -> float:
    """Return the best time of one call (seconds) over `repeat` × `number` calls."""
    return min(timeit.repeat(fn, repeat=repeat, number=number)) / number


def main() -> None:
    rng = np.random.default_rng(1)
    truth = model_from_values({t: float(v) for t, v in zip(TERMS, rng.normal(0, 30, len(TERMS)),
                                                          strict=True)})
    run = simulate_run(truth, N_OBS, 1.0, rng=rng, min_el_deg=15.0)
    az, el = np.radians(run.obs_az_deg), np.radians(run.obs_el_deg)
    x = design_matrix(TERMS, az, el)
    y = np.concatenate(run.residuals_rad())

    t_fit = best_of(lambda: fit_run(run, TERMS))
    t_numpy = best_of(lambda: np.linalg.lstsq(x, y, rcond=None))
    t_matrix = best_of(lambda: design_matrix(TERMS, az, el))
    t_auto = best_of(lambda: select_terms(run), repeat=3, number=1)
    result = fit_run(run, TERMS)
    print(f"fit of {N_OBS} observations × {len(TERMS)} terms "
          f"(sky RMS {result.sky_rms_arcsec:.3f}″, cond {result.condition_number:.3g})")
    print(f"  pointing_model.fit_run (everything)       {t_fit * 1e3:8.2f} ms   goal ≤ {GOAL_S * 1e3:.0f} ms"
          f"   {'OK' if t_fit <= GOAL_S else 'MISSED'}")
    print(f"  reference: numpy.linalg.lstsq same matrix {t_numpy * 1e3:8.2f} ms")
    print(f"  reference: building the design matrix     {t_matrix * 1e3:8.2f} ms")
    print(f"  (for information) --auto forward selection {t_auto * 1e3:7.2f} ms")


if __name__ == "__main__":
    main()
