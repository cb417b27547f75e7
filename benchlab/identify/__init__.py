"""Grey-box identification of thermal networks from run files (output-error, nonlinear least squares)."""

from benchlab.identify.data import FitData, prepare
from benchlab.identify.fit import FitResult, fit, fit_multistart
from benchlab.identify.spec import ModelSpec, ParamSpec, clutch_spec

__all__ = ["FitData", "prepare", "FitResult", "fit", "fit_multistart", "ModelSpec", "ParamSpec", "clutch_spec"]
