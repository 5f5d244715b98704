"""Fit TPOINT terms to a pointing run by linear least squares (scipy), as TPOINT reports it.

Statistics (N observations used, M terms, r = residual after the fit, per observation the
sky residual r_S = ΔA·cos E and r_E = ΔE; X the 2N×M design matrix in radians):

- sky RMS          sqrt(Σ(r_S² + r_E²) / N)
- PSD              sqrt(Σ(r_S² + r_E²) / (N − M))        TPOINT's population SD
- σ (TPOINT)       sky RMS × sqrt(diag((XᵀX)⁻¹))        reproduces TPOINT's published σ
- σ (statistical)  sqrt(Σr² / (2N − M)) × sqrt(diag((XᵀX)⁻¹))   the 1-σ error if each
                   coordinate carries independent Gaussian noise; σ_TPOINT ≈ √2 × this
- leave-one-out RMS  sky RMS of the residual of each observation predicted by a fit
                   without it: e_(i) = (I − H_ii)⁻¹ e_i with H_ii the observation's 2×2
                   block of the hat matrix (closed form, no refits)
- condition number of X with its columns scaled to unit length (scale-free).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.linalg
import scipy.stats

from .constants import (
    ARCSEC_PER_RAD,
    AUTO_ALPHA,
    AUTO_BASE_TERMS,
    AUTO_CANDIDATE_TERMS,
    AUTO_MAX_CORRELATION,
    REPORT_CORRELATION,
)
from .exceptions import FitError
from .model import PointingModel
from .runs import PointingRun
from .terms import design_matrix, parse_term_list


@dataclass(frozen=True)
class SelectionStep:
    """One step of automatic term selection: the term tried best and its F-test."""

    term: str
    f_statistic: float
    p_value: float
    candidates_tried: int
    accepted: bool


@dataclass(frozen=True)
class FitResult:
    """Everything a fit reports; arcseconds throughout. Arrays over all N_total records."""

    terms: tuple[str, ...]
    values_arcsec: np.ndarray
    sigmas_arcsec: np.ndarray  # TPOINT convention (sky RMS × sqrt diag (XᵀX)⁻¹)
    sigmas_stat_arcsec: np.ndarray  # statistical standard error
    sky_rms_arcsec: float
    psd_arcsec: float
    loo_rms_arcsec: float
    raw_sky_rms_arcsec: float
    condition_number: float
    correlation: np.ndarray
    high_correlations: tuple[tuple[str, str, float], ...]
    used: np.ndarray  # bool per record
    residual_s_arcsec: np.ndarray  # ΔA·cos E after the model, every record
    residual_e_arcsec: np.ndarray
    source: str = "<run>"
    line_numbers: tuple[int, ...] = ()
    selection: tuple[SelectionStep, ...] = field(default=())
    masked_lines: tuple[int, ...] = ()  # records masked with ';' in the file, never read

    @property
    def n_masked(self) -> int:
        """Records the file masks with a leading ';' (skipped, as TPOINT does)."""
        return len(self.masked_lines)

    @property
    def n_obs(self) -> int:
        """Observations used in the final fit."""
        return int(np.count_nonzero(self.used))

    @property
    def n_rejected(self) -> int:
        """Observations removed by --reject-sigma."""
        return int(self.used.size - self.n_obs)

    @property
    def model(self) -> PointingModel:
        """Return the fitted model (values and TPOINT σ)."""
        return PointingModel(self.terms, tuple(self.values_arcsec), tuple(self.sigmas_arcsec),
                             self.summary())

    def summary(self) -> dict[str, Any]:
        """Return the fit statistics (no per-term values) as plain JSON types."""
        return {
            "source": self.source,
            "sky_rms_arcsec": self.sky_rms_arcsec,
            "psd_arcsec": self.psd_arcsec,
            "loo_rms_arcsec": self.loo_rms_arcsec,
            "raw_sky_rms_arcsec": self.raw_sky_rms_arcsec,
            "n_obs": self.n_obs,
            "n_rejected": self.n_rejected,
            "n_masked": self.n_masked,
            "condition_number": self.condition_number,
        }

    def to_json_dict(self) -> dict[str, Any]:
        """Return the `pointing-model fit --json` document."""
        doc: dict[str, Any] = {
            "terms": {
                name: {"value_arcsec": float(v), "sigma_arcsec": float(s),
                       "sigma_stat_arcsec": float(ss)}
                for name, v, s, ss in zip(self.terms, self.values_arcsec, self.sigmas_arcsec,
                                          self.sigmas_stat_arcsec, strict=True)
            },
        }
        doc.update(self.summary())
        doc["sigma_convention"] = "TPOINT: sky_rms * sqrt(diag(inv(X^T X)))"
        rejected = np.flatnonzero(~self.used)
        doc["rejected_lines"] = ([self.line_numbers[i] for i in rejected] if self.line_numbers
                                 else [int(i) + 1 for i in rejected])
        doc["high_correlations"] = [{"terms": [a, b], "r": r} for a, b, r in self.high_correlations]
        doc["masked_lines"] = list(self.masked_lines)
        if self.selection:
            doc["selection"] = [dict(step.__dict__) for step in self.selection]
        return _json_safe(doc)


def _json_safe(value: Any) -> Any:
    """Return `value` with non-finite floats replaced by None (JSON has no inf or NaN)."""
    if isinstance(value, dict):
        return {k: _json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_json_safe(v) for v in value]
    if isinstance(value, float | np.floating):
        return float(value) if np.isfinite(value) else None
    return value


@dataclass(frozen=True)
class _Solution:
    coeffs: np.ndarray
    rank: int
    singular_values: np.ndarray
    rss: float


def _solve(x: np.ndarray, y: np.ndarray) -> _Solution:
    coeffs, _, rank, sv = scipy.linalg.lstsq(x, y, lapack_driver="gelsd", check_finite=False)
    r = y - x @ coeffs
    return _Solution(coeffs, int(rank), sv, float(r @ r))


def fit_run(run: PointingRun, terms: Sequence[str] | str, *,
            reject_sigma: float | None = None) -> FitResult:
    """Fit `terms` to `run`; with `reject_sigma` K, drop outliers one at a time.

    Rejection removes the observation with the largest sky residual while it exceeds
    K × sky RMS of the current fit, then refits, until none does. Raises FitError when the
    data cannot determine the terms (too few observations, degenerate terms).
    """
    names = parse_term_list(terms)
    if reject_sigma is not None and not reject_sigma > 0:
        raise ValueError(f"reject_sigma must be positive, got {reject_sigma}")
    used = np.ones(len(run), dtype=bool)
    az, el = np.radians(run.obs_az_deg), np.radians(run.obs_el_deg)
    x_all = design_matrix(names, az, el)
    res_s, res_e = run.residuals_rad()
    while True:
        result = _fit_subset(run, names, x_all, res_s, res_e, used)
        if reject_sigma is None:
            return result
        dist = np.hypot(result.residual_s_arcsec, result.residual_e_arcsec)
        dist[~used] = -np.inf
        worst = int(np.argmax(dist))
        if dist[worst] <= reject_sigma * result.sky_rms_arcsec:
            return result
        if np.count_nonzero(used) - 1 <= len(names):
            return result
        used[worst] = False


def _fit_subset(run: PointingRun, names: tuple[str, ...], x_all: np.ndarray,
                res_s: np.ndarray, res_e: np.ndarray, used: np.ndarray) -> FitResult:
    n_total = len(run)
    n, m = int(np.count_nonzero(used)), len(names)
    if n <= m:
        raise FitError(f"{n} observations cannot determine {m} terms; need more than {m}")
    rows = np.concatenate([used, used])
    x = x_all[rows]
    y = np.concatenate([res_s[used], res_e[used]])
    sol = _solve(x, y)
    norms = np.linalg.norm(x, axis=0)
    if sol.rank < m or np.any(norms == 0):
        raise FitError(_degenerate_message(names, x, norms))
    cond = _condition_number(x / norms)
    q, r_mat = scipy.linalg.qr(x, mode="economic", check_finite=False)
    r_inv = scipy.linalg.solve_triangular(r_mat, np.eye(m), check_finite=False)
    cov = r_inv @ r_inv.T  # (XᵀX)⁻¹
    resid = y - x @ sol.coeffs
    rs, re = resid[:n], resid[n:]
    sky_ss = float(np.sum(rs**2 + re**2))
    sky_rms = np.sqrt(sky_ss / n) * ARCSEC_PER_RAD
    psd = np.sqrt(sky_ss / (n - m)) * ARCSEC_PER_RAD
    diag = np.sqrt(np.diag(cov))
    stat = np.sqrt(sky_ss / (2 * n - m)) * ARCSEC_PER_RAD
    corr = cov / np.outer(diag, diag)
    pred = x_all @ sol.coeffs
    return FitResult(
        terms=names,
        values_arcsec=sol.coeffs * ARCSEC_PER_RAD,
        sigmas_arcsec=sky_rms * diag,
        sigmas_stat_arcsec=stat * diag,
        sky_rms_arcsec=float(sky_rms),
        psd_arcsec=float(psd),
        loo_rms_arcsec=_loo_rms(q[:n], q[n:], rs, re) * ARCSEC_PER_RAD,
        raw_sky_rms_arcsec=run.subset(used).raw_sky_rms_arcsec(),
        condition_number=cond,
        correlation=corr,
        high_correlations=_high_correlations(names, corr),
        used=used.copy(),
        residual_s_arcsec=(res_s - pred[:n_total]) * ARCSEC_PER_RAD,
        residual_e_arcsec=(res_e - pred[n_total:]) * ARCSEC_PER_RAD,
        source=run.source,
        line_numbers=run.line_numbers,
        masked_lines=run.masked_lines,
    )


def _loo_rms(qs: np.ndarray, qe: np.ndarray, rs: np.ndarray, re: np.ndarray) -> float:
    # Hat matrix H = QQᵀ; observation i owns rows i (S) and N+i (E): a 2×2 block.
    h_ss = np.einsum("ij,ij->i", qs, qs)
    h_se = np.einsum("ij,ij->i", qs, qe)
    h_ee = np.einsum("ij,ij->i", qe, qe)
    a, b, d = 1.0 - h_ss, -h_se, 1.0 - h_ee
    det = a * d - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        loo_s = (d * rs - b * re) / det
        loo_e = (-b * rs + a * re) / det
    return float(np.sqrt(np.mean(loo_s**2 + loo_e**2)))


def _condition_number(x_unit: np.ndarray) -> float:
    sv = scipy.linalg.svdvals(x_unit, check_finite=False)
    return float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf")


def _high_correlations(names: tuple[str, ...], corr: np.ndarray
                       ) -> tuple[tuple[str, str, float], ...]:
    out = []
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            if abs(corr[i, j]) > REPORT_CORRELATION:
                out.append((names[i], names[j], float(corr[i, j])))
    return tuple(out)


def _degenerate_message(names: tuple[str, ...], x: np.ndarray, norms: np.ndarray) -> str:
    zero = [names[j] for j in range(len(names)) if norms[j] == 0]
    if zero:
        return f"term(s) {', '.join(zero)} have no effect at these positions; remove them"
    _, _, vt = scipy.linalg.svd(x / norms, full_matrices=False)
    null = vt[-1]
    involved = [names[j] for j in np.flatnonzero(np.abs(null) > 0.1)]
    return (f"terms {', '.join(involved)} cannot be told apart with these observations "
            "(design matrix is singular); drop one of them or observe a wider range of sky")


def select_terms(run: PointingRun, *, base: Sequence[str] = AUTO_BASE_TERMS,
                 candidates: Sequence[str] = AUTO_CANDIDATE_TERMS, alpha: float = AUTO_ALPHA,
                 reject_sigma: float | None = None) -> FitResult:
    """Choose terms by forward selection and return the final fit.

    Starting from `base`, each step fits every remaining candidate in turn and takes the one
    that lowers the residual sum of squares most. It is kept if its partial F-test
    F = (RSS_before − RSS_after) / (RSS_after / (2N − M_after)), with 1 and 2N − M_after
    degrees of freedom, has p × (candidates tried) < `alpha` (Bonferroni), and it is not
    correlated above 0.995 with a chosen term; otherwise selection stops. Outlier rejection,
    if asked, is applied to the final fit.
    """
    chosen = list(parse_term_list(base))
    pool = [t for t in parse_term_list(candidates) if t not in chosen]
    res_s, res_e = run.residuals_rad()
    y = np.concatenate([res_s, res_e])
    az, el = np.radians(run.obs_az_deg), np.radians(run.obs_el_deg)
    n = len(run)
    x_cur = design_matrix(chosen, az, el)
    rss_cur = _solve(x_cur, y).rss
    steps: list[SelectionStep] = []
    floor = 1e-16 * float(y @ y)  # residual 1e-8 of the signal: rounding, not pointing
    while pool and rss_cur > floor:
        best: tuple[float, str, np.ndarray] | None = None
        tried = 0
        for term in pool:
            x_try = np.column_stack([x_cur, design_matrix([term], az, el)])
            if 2 * n - x_try.shape[1] <= 0 or n <= x_try.shape[1]:
                continue
            sol = _solve(x_try, y)
            if sol.rank < x_try.shape[1] or _max_corr_with_last(x_try) > AUTO_MAX_CORRELATION:
                continue
            tried += 1
            if best is None or sol.rss < best[0]:
                best = (sol.rss, term, x_try)
        if best is None:
            break
        rss_new, term, x_new = best
        dof = 2 * n - x_new.shape[1]
        f_stat = (rss_cur - rss_new) / (rss_new / dof) if rss_new > 0 else np.inf
        p = float(scipy.stats.f.sf(f_stat, 1, dof))
        accepted = p * tried < alpha
        steps.append(SelectionStep(term, float(f_stat), p, tried, accepted))
        if not accepted:
            break
        chosen.append(term)
        pool.remove(term)
        x_cur, rss_cur = x_new, rss_new
    result = fit_run(run, chosen, reject_sigma=reject_sigma)
    return _with_selection(result, tuple(steps))


def _max_corr_with_last(x: np.ndarray) -> float:
    cov = np.linalg.pinv(x.T @ x)
    d = np.sqrt(np.abs(np.diag(cov)))
    corr = cov[-1, :-1] / (d[-1] * d[:-1])
    return float(np.max(np.abs(corr), initial=0.0))


def _with_selection(result: FitResult, steps: tuple[SelectionStep, ...]) -> FitResult:
    fields = dict(result.__dict__)
    fields["selection"] = steps
    return FitResult(**fields)
