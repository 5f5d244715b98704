"""TPOINT alt-az pointing terms as columns of a linear design matrix.

Convention (see docs/pointing-model.md): the residual is observed − raw (encoder), every
term is evaluated at the observed position (A, E in radians, A as written in the data,
E the elevation), and the azimuth residual is fitted as a sky distance ΔS = ΔA·cos E.
A term with coefficient c contributes c·s(A, E) to ΔS and c·e(A, E) to ΔE; `columns`
returns the pair (s, e) for unit coefficient.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from .exceptions import UnknownTermError

Columns = tuple[np.ndarray, np.ndarray]


def _ia(a: np.ndarray, e: np.ndarray) -> Columns:
    return -np.cos(e), np.zeros_like(e)  # ΔA = −IA


def _ie(a: np.ndarray, e: np.ndarray) -> Columns:
    return np.zeros_like(e), np.ones_like(e)  # ΔE = +IE


def _ca(a: np.ndarray, e: np.ndarray) -> Columns:
    return -np.ones_like(e), np.zeros_like(e)  # ΔA = −CA sec E


def _npae(a: np.ndarray, e: np.ndarray) -> Columns:
    return -np.sin(e), np.zeros_like(e)  # ΔA = −NPAE tan E


def _an(a: np.ndarray, e: np.ndarray) -> Columns:
    return -np.sin(a) * np.sin(e), -np.cos(a)  # ΔA = −AN sin A tan E, ΔE = −AN cos A


def _aw(a: np.ndarray, e: np.ndarray) -> Columns:
    return -np.cos(a) * np.sin(e), np.sin(a)  # ΔA = −AW cos A tan E, ΔE = +AW sin A


def _tf(a: np.ndarray, e: np.ndarray) -> Columns:
    return np.zeros_like(e), -np.cos(e)  # ΔE = −TF cos E


def _tx(a: np.ndarray, e: np.ndarray) -> Columns:
    return np.zeros_like(e), -np.cos(e) / np.sin(e)  # ΔE = −TX cot E


def _acec(a: np.ndarray, e: np.ndarray) -> Columns:
    return np.cos(a) * np.cos(e), np.zeros_like(e)  # ΔA = +ACEC cos A


def _aces(a: np.ndarray, e: np.ndarray) -> Columns:
    # TPOINT's ACES is its HASA, evaluated with A_T = 180° − A: ΔA = −ACES sin A
    return -np.sin(a) * np.cos(e), np.zeros_like(e)


def _ecec(a: np.ndarray, e: np.ndarray) -> Columns:
    return np.zeros_like(e), np.cos(e)  # ΔE = +ECEC cos E


def _eces(a: np.ndarray, e: np.ndarray) -> Columns:
    return np.zeros_like(e), np.sin(e)  # ΔE = +ECES sin E


@dataclass(frozen=True)
class Term:
    """One pointing term: its TPOINT name, a one-line meaning and its column function."""

    name: str
    meaning: str
    columns: Callable[[np.ndarray, np.ndarray], Columns]


NAMED_TERMS: dict[str, Term] = {
    t.name: t
    for t in (
        Term("IA", "azimuth index error (encoder zero point)", _ia),
        Term("IE", "elevation index error (encoder zero point)", _ie),
        Term("CA", "left-right collimation error (optical axis ⟂ elevation axis)", _ca),
        Term("NPAE", "azimuth/elevation axes non-perpendicularity", _npae),
        Term("AN", "azimuth axis tilted north-south", _an),
        Term("AW", "azimuth axis tilted east-west", _aw),
        Term("TF", "tube flexure ∝ cos E", _tf),
        Term("TX", "tube flexure ∝ cot E", _tx),
        Term("ACEC", "azimuth encoder centring, cosine component", _acec),
        Term("ACES", "azimuth encoder centring, sine component", _aces),
        Term("ECEC", "elevation encoder centring, cosine component", _ecec),
        Term("ECES", "elevation encoder centring, sine component", _eces),
    )
}

# H, result letter, then one or two factors: S(in)/C(os), coordinate A/E/Z, frequency.
_HARMONIC = re.compile(r"^H([AESZ])((?:[SC][AEZ]\d{0,2}){1,2})$")
_FACTOR = re.compile(r"([SC])([AEZ])(\d{0,2})")
_RESULTS = {"A": "−ΔA", "E": "ΔE", "S": "−ΔA·cos E", "Z": "ΔZ = −ΔE"}


def _harmonic(name: str) -> Term:
    match = _HARMONIC.match(name)
    if match is None:
        raise UnknownTermError(
            name,
            "expected one of " + ", ".join(NAMED_TERMS)
            + " or a harmonic H<A|E|S|Z><S|C><A|E|Z>[n][<S|C><A|E|Z>[n]] such as HASA2, HSCA5CE8",
        )
    result, factor_text = match.groups()
    factors = []
    for func, coord, freq_text in _FACTOR.findall(factor_text):
        freq = int(freq_text) if freq_text else 1
        if freq == 0:
            raise UnknownTermError(name, "a harmonic frequency must be 1 or more")
        factors.append((func, coord, freq))

    def columns(a: np.ndarray, e: np.ndarray) -> Columns:
        # TPOINT evaluates harmonics in its own alt-az frame, azimuth reckoned from the
        # south through east: A_T = π − A. Its azimuth-type results are corrections to A_T,
        # i.e. −ΔA in our north-through-east azimuth (docs/pointing-model.md).
        a_tpoint = np.pi - a
        value = np.ones_like(e)
        for func, coord, freq in factors:
            angle = {"A": a_tpoint, "E": e, "Z": np.pi / 2 - e}[coord] * freq
            value = value * (np.sin(angle) if func == "S" else np.cos(angle))
        zero = np.zeros_like(e)
        if result == "A":
            return -value * np.cos(e), zero
        if result == "S":
            return -value, zero
        if result == "E":
            return zero, value
        return zero, -value  # Z: zenith distance grows as elevation falls

    text = " × ".join(f"{'sin' if f == 'S' else 'cos'}({n if n > 1 else ''}"
                      f"{'A_T' if c == 'A' else c})" for f, c, n in factors)
    if "A" in (c for _, c, _ in factors):
        text += ", A_T = 180° − A"
    return Term(name, f"harmonic: {_RESULTS[result]} = {name} × {text}", columns)


# TPOINT terms this package knows by name but does not implement: refused with the reason,
# never silently dropped (docs/pointing-model.md, "TPOINT terms not implemented").
_EQUATORIAL = "an equatorial-mount term; only alt-az models are supported"
TPOINT_TERMS_NOT_IMPLEMENTED: dict[str, str] = {
    "TX10": ("TPOINT's TX variant whose definition is not published in a form we could verify; "
             "on runs well above the horizon it equals TX to 0.01″ (AuxTel 2022-04: TX10 "
             "11.92″, TX 11.93″): substitute TX explicitly (--substitute TX10=TX) if that holds for your data"),
    "NRX": "a Nasmyth rotator term (rotator terms are not implemented)",
    "NRY": "a Nasmyth rotator term (rotator terms are not implemented)",
    **{name: _EQUATORIAL for name in ("IH", "ID", "CH", "NP", "MA", "ME", "FO", "DAF", "HCEC",
                                      "HCES", "DCEC", "DCES", "PDD", "HDSD", "HDCD")},
}


@lru_cache(maxsize=512)
def get_term(name: str) -> Term:
    """Return the term called `name` (case-insensitive); raises UnknownTermError."""
    key = name.strip().upper()
    if key in NAMED_TERMS:
        return NAMED_TERMS[key]
    if key in TPOINT_TERMS_NOT_IMPLEMENTED:
        raise UnknownTermError(key, f"not implemented: {TPOINT_TERMS_NOT_IMPLEMENTED[key]}")
    return _harmonic(key)


def parse_term_list(text: str | Iterable[str]) -> tuple[str, ...]:
    """Parse "IA,IE,CA" (or an iterable of names) into canonical upper-case names.

    Raises UnknownTermError for an unknown name and ValueError for a repeated one.
    """
    names = text.replace(" ", ",").split(",") if isinstance(text, str) else list(text)
    result: list[str] = []
    for raw in names:
        if not raw.strip():
            continue
        name = get_term(raw).name
        if name in result:
            raise ValueError(f"term {name} is listed twice")
        result.append(name)
    if not result:
        raise ValueError("no terms given; expected a list such as IA,IE,CA,AN,AW")
    return tuple(result)


def design_matrix(terms: Sequence[str], az_rad: np.ndarray, el_rad: np.ndarray) -> np.ndarray:
    """Return the (2N, M) design matrix: rows 0..N-1 give ΔA·cos E, rows N..2N-1 give ΔE.

    Entry [i, j] is the effect of a unit coefficient of term j on observation i, both in
    radians; positions are the observed ones in radians.
    """
    az = np.asarray(az_rad, dtype=float)
    el = np.asarray(el_rad, dtype=float)
    n = az.shape[0]
    x = np.empty((2 * n, len(terms)))
    for j, name in enumerate(terms):
        s, e = get_term(name).columns(az, el)
        x[:n, j] = s
        x[n:, j] = e
    return x
