"""TPOINT-style pointing model for alt-azimuth mounts: terms, fit, apply and invert.

The VSS uses::

    from pointing_model import load_model
    model = load_model("model.json")
    enc_az_deg, enc_el_deg = model.observed_to_encoder(obs_az_deg, obs_el_deg)   # arrays
    obs_az_deg, obs_el_deg = model.encoder_to_observed(enc_az_deg, enc_el_deg)
"""

from importlib import import_module
from typing import TYPE_CHECKING, Any

from .exceptions import (
    ConvergenceError,
    DataFormatError,
    FitError,
    ModelFileError,
    PointingModelError,
    UnknownTermError,
)

# The rest (numpy, scipy) is imported on first use: `pointing-model --help` and a caller
# that needs only the errors stay fast (tests/test_import_rules.py).
_LAZY = {
    "load_csv": "csv_format", "read_csv": "csv_format",
    "FitResult": "fitting", "SelectionStep": "fitting", "fit_run": "fitting",
    "select_terms": "fitting",
    "PointingModel": "model", "load_model": "model", "model_from_text": "model",
    "model_from_values": "model",
    "load_run": "run_files",
    "PointingRun": "runs", "RunParameters": "runs", "wrap_deg_180": "runs",
    "simulate_run": "simulate",
    "even_sky_positions": "sky_sampling", "pick_spread": "sky_sampling",
    "NAMED_TERMS": "terms", "Term": "terms", "design_matrix": "terms", "get_term": "terms",
    "parse_term_list": "terms",
    "load_tpoint": "tpoint_format", "read_tpoint": "tpoint_format",
    "write_tpoint": "tpoint_format",
}

if TYPE_CHECKING:
    from .csv_format import load_csv, read_csv
    from .fitting import FitResult, SelectionStep, fit_run, select_terms
    from .model import PointingModel, load_model, model_from_text, model_from_values
    from .run_files import load_run
    from .runs import PointingRun, RunParameters, wrap_deg_180
    from .simulate import simulate_run
    from .sky_sampling import even_sky_positions, pick_spread
    from .terms import NAMED_TERMS, Term, design_matrix, get_term, parse_term_list
    from .tpoint_format import load_tpoint, read_tpoint, write_tpoint


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


__all__ = [
    "NAMED_TERMS",
    "ConvergenceError",
    "DataFormatError",
    "FitError",
    "FitResult",
    "ModelFileError",
    "PointingModel",
    "PointingModelError",
    "PointingRun",
    "RunParameters",
    "SelectionStep",
    "Term",
    "UnknownTermError",
    "design_matrix",
    "even_sky_positions",
    "fit_run",
    "get_term",
    "load_csv",
    "load_model",
    "load_run",
    "load_tpoint",
    "model_from_text",
    "model_from_values",
    "parse_term_list",
    "pick_spread",
    "read_csv",
    "read_tpoint",
    "select_terms",
    "simulate_run",
    "wrap_deg_180",
    "write_tpoint",
]
