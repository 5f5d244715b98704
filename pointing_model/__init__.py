"""TPOINT-style pointing model for alt-azimuth mounts: terms, fit, apply and invert.

The VSS uses::

    from pointing_model import load_model
    model = load_model("model.json")
    enc_az_deg, enc_el_deg = model.observed_to_encoder(obs_az_deg, obs_el_deg)   # arrays
    obs_az_deg, obs_el_deg = model.encoder_to_observed(enc_az_deg, enc_el_deg)
"""

from .csv_format import load_csv, read_csv
from .exceptions import (
    ConvergenceError,
    DataFormatError,
    FitError,
    ModelFileError,
    PointingModelError,
    UnknownTermError,
)
from .fitting import FitResult, SelectionStep, fit_run, select_terms
from .model import PointingModel, load_model, model_from_text, model_from_values
from .run_files import load_run
from .runs import PointingRun, RunParameters, wrap_deg_180
from .simulate import simulate_run
from .sky_sampling import even_sky_positions, pick_spread
from .terms import NAMED_TERMS, Term, design_matrix, get_term, parse_term_list
from .tpoint_format import load_tpoint, read_tpoint, write_tpoint

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
