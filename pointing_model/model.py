"""A fitted pointing model: apply it (observed → encoder demand), invert it, save and load it.

Terms are evaluated at the observed position, so observed → encoder is explicit:
    A_enc = A_obs − ΔS(A_obs, E_obs) / cos E_obs,   E_enc = E_obs − ΔE(A_obs, E_obs);
encoder → observed solves A_obs = A_enc + ΔA(A_obs, E_obs) by fixed-point iteration.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .constants import ARCSEC_PER_RAD, INVERT_MAX_ITERATIONS, INVERT_TOLERANCE_ARCSEC
from .exceptions import ConvergenceError, ModelFileError, UnknownTermError
from .terms import design_matrix, parse_term_list

MODEL_FORMAT = "virtualstar-pointing-model"
MODEL_FORMAT_VERSION = 1


@dataclass(frozen=True)
class PointingModel:
    """Terms and coefficients (arcsec) of an alt-az pointing model.

    `sigmas_arcsec` (TPOINT convention) and `fit_info` are informative and optional.
    """

    terms: tuple[str, ...]
    values_arcsec: tuple[float, ...]
    sigmas_arcsec: tuple[float, ...] | None = None
    fit_info: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        terms = parse_term_list(self.terms)
        object.__setattr__(self, "terms", terms)
        object.__setattr__(self, "values_arcsec", tuple(float(v) for v in self.values_arcsec))
        if len(self.values_arcsec) != len(terms):
            raise ValueError(f"{len(terms)} terms but {len(self.values_arcsec)} values")
        if self.sigmas_arcsec is not None:
            object.__setattr__(self, "sigmas_arcsec", tuple(float(s) for s in self.sigmas_arcsec))
            if len(self.sigmas_arcsec) != len(terms):
                raise ValueError(f"{len(terms)} terms but {len(self.sigmas_arcsec)} sigmas")

    @classmethod
    def from_mapping(cls, values_arcsec: Mapping[str, float]) -> PointingModel:
        """Build a model from {"IA": -292.0, ...} (arcsec)."""
        return cls(tuple(values_arcsec), tuple(values_arcsec.values()))

    def as_dict(self) -> dict[str, float]:
        """Return {term: value_arcsec}."""
        return dict(zip(self.terms, self.values_arcsec, strict=True))

    # -- evaluation ---------------------------------------------------------------------
    def offsets_rad(self, az_rad: np.ndarray, el_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return (ΔA·cos E, ΔE) in radians at observed positions (radians): observed − encoder."""
        az, el = np.broadcast_arrays(np.asarray(az_rad, dtype=float),
                                     np.asarray(el_rad, dtype=float))
        if not self.terms:
            return np.zeros(az.shape), np.zeros(el.shape)
        coeffs = np.asarray(self.values_arcsec) / ARCSEC_PER_RAD
        d = design_matrix(self.terms, az.ravel(), el.ravel()) @ coeffs
        n = az.size
        return d[:n].reshape(az.shape), d[n:].reshape(az.shape)

    def _corrections_rad(self, az: np.ndarray, el: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ds, de = self.offsets_rad(az, el)
        cos_el = np.cos(el)
        # At the zenith azimuth is undefined; floating-point cos(90°) is 6e-17, not 0.
        with np.errstate(divide="ignore", invalid="ignore"):
            da = np.where(np.abs(cos_el) < 1e-12, np.where(ds == 0.0, 0.0, np.nan), ds / cos_el)
        return da, de

    def observed_to_encoder(self, az_deg: Any, el_deg: Any) -> tuple[np.ndarray, np.ndarray]:
        """Return the encoder demand (az_deg, el_deg) that puts an observed position on axis.

        Inputs are observed (refracted) azimuth and elevation in degrees, scalars or arrays;
        the azimuth keeps the input's wrap. Raises ValueError where the model is undefined
        (elevation ≤ 0° with TX, 90° with azimuth terms).
        """
        az, el = _as_radians(az_deg, el_deg)
        da, de = self._corrections_rad(az, el)
        _check_finite(da, de, "observed_to_encoder")
        return np.degrees(az - da), np.degrees(el - de)

    def encoder_to_observed(self, az_deg: Any, el_deg: Any, *,
                            tolerance_arcsec: float = INVERT_TOLERANCE_ARCSEC,
                            max_iterations: int = INVERT_MAX_ITERATIONS,
                            ) -> tuple[np.ndarray, np.ndarray]:
        """Return the observed position (az_deg, el_deg) seen on axis at encoder readings (deg).

        Fixed-point iteration of observed = encoder + Δ(observed); raises ConvergenceError
        if a step still moves more than `tolerance_arcsec` after `max_iterations`.
        """
        enc_az, enc_el = _as_radians(az_deg, el_deg)
        az, el = enc_az.copy(), enc_el.copy()
        tolerance_rad = tolerance_arcsec / ARCSEC_PER_RAD
        for _ in range(max_iterations):
            da, de = self._corrections_rad(az, el)
            _check_finite(da, de, "encoder_to_observed")
            new_az, new_el = enc_az + da, enc_el + de
            step = max(float(np.max(np.abs(new_az - az) * np.cos(el), initial=0.0)),
                       float(np.max(np.abs(new_el - el), initial=0.0)))
            az, el = new_az, new_el
            if step <= tolerance_rad:
                return np.degrees(az), np.degrees(el)
        raise ConvergenceError(
            f"encoder → observed did not converge in {max_iterations} steps "
            f"(last step {step * ARCSEC_PER_RAD:.3g} arcsec); is a position near the zenith?"
        )

    # -- JSON -----------------------------------------------------------------------------
    def to_json_dict(self) -> dict[str, Any]:
        """Return the JSON document of this model (format in docs/pointing-model.md)."""
        terms: dict[str, dict[str, float]] = {}
        for i, name in enumerate(self.terms):
            entry = {"value_arcsec": self.values_arcsec[i]}
            if self.sigmas_arcsec is not None:
                entry["sigma_arcsec"] = self.sigmas_arcsec[i]
            terms[name] = entry
        return {
            "format": MODEL_FORMAT,
            "version": MODEL_FORMAT_VERSION,
            "convention": "observed - encoder; terms at observed position; "
                          "azimuth residual as dA*cos(E); TPOINT names and signs",
            "terms": terms,
            "fit": dict(self.fit_info),
        }

    @classmethod
    def from_json_dict(cls, doc: Any, source: str = "<model>") -> PointingModel:
        """Build a model from a JSON document; raises ModelFileError naming what is wrong."""
        if not isinstance(doc, dict):
            raise ModelFileError(source, "expected a JSON object with a \"terms\" member")
        if doc.get("format", MODEL_FORMAT) != MODEL_FORMAT:
            raise ModelFileError(source, f"format is {doc.get('format')!r}, expected {MODEL_FORMAT!r}")
        terms = doc.get("terms")
        if not isinstance(terms, dict):
            raise ModelFileError(
                source, 'expected "terms": {"IA": {"value_arcsec": ...}, ...}')
        names, values, sigmas = [], [], []
        for name, entry in terms.items():
            value = entry.get("value_arcsec") if isinstance(entry, dict) else entry
            if not isinstance(value, int | float) or not math.isfinite(value):
                raise ModelFileError(source, f"term {name}: value_arcsec must be a finite number")
            names.append(name)
            values.append(float(value))
            sigma = entry.get("sigma_arcsec") if isinstance(entry, dict) else None
            sigmas.append(float(sigma) if isinstance(sigma, int | float) else math.nan)
        fit = doc.get("fit", {})
        try:
            return cls(tuple(names), tuple(values),
                       None if all(math.isnan(s) for s in sigmas) else tuple(sigmas),
                       fit if isinstance(fit, dict) else {})
        except (UnknownTermError, ValueError) as exc:
            raise ModelFileError(source, str(exc)) from exc

    def save(self, path: str | Path) -> None:
        """Write the model as JSON to `path`."""
        Path(path).write_text(json.dumps(self.to_json_dict(), indent=2) + "\n", encoding="utf-8")


def load_model(path: str | Path, *, substitute: Mapping[str, str] | None = None
               ) -> PointingModel:
    """Read a model file: our JSON, or TPOINT's `.mod` layout (recognised by its `T` line).

    `substitute` is passed to the TPOINT reader (e.g. {"TX10": "TX"}). Raises
    ModelFileError (also for unreadable files and files in neither format).
    """
    source = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise ModelFileError(source, f"cannot read: {exc.strerror or exc}") from exc
    return model_from_text(text, source, substitute=substitute)


def model_from_text(text: str, source: str, *, substitute: Mapping[str, str] | None = None
                    ) -> PointingModel:
    """Read a model from the `text` of a file named `source` (as `load_model` does)."""
    from .tpoint_model_file import looks_like_tpoint_model, read_tpoint_model

    if looks_like_tpoint_model(text):
        return read_tpoint_model(text.splitlines(), source, substitute=substitute)
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ModelFileError(source, f"not JSON (line {exc.lineno}: {exc.msg}) "
                             "and not a TPOINT model (caption, then a 'T N_OBS SKY_RMS' line)"
                             ) from exc
    return PointingModel.from_json_dict(doc, source)


def model_from_values(values_arcsec: Mapping[str, float] | Sequence[tuple[str, float]]
                      ) -> PointingModel:
    """Build a model from {"IA": -30.0, ...} or [("IA", -30.0), ...] (arcsec)."""
    items = list(values_arcsec.items()) if isinstance(values_arcsec, Mapping) else list(values_arcsec)
    return PointingModel(tuple(n for n, _ in items), tuple(v for _, v in items))


def _as_radians(az_deg: Any, el_deg: Any) -> tuple[np.ndarray, np.ndarray]:
    az, el = np.broadcast_arrays(np.asarray(az_deg, dtype=float), np.asarray(el_deg, dtype=float))
    if np.any(np.abs(el) > 90.0):
        raise ValueError("elevation must lie within [-90, 90] degrees")
    return np.radians(az), np.radians(el)


def _check_finite(da: np.ndarray, de: np.ndarray, what: str) -> None:
    bad = ~(np.isfinite(da) & np.isfinite(de))
    if np.any(bad):
        raise ValueError(
            f"{what}: the model is undefined at {int(np.count_nonzero(bad))} position(s) "
            "(elevation 90° for azimuth terms, 0° for TX); keep 0° < E < 90°"
        )
