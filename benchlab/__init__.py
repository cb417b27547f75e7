"""benchlab: dry-clutch test-bench acquisition and grey-box thermal modelling (contract section 4)."""

from benchlab.params import load_params
from benchlab.runfile import load_run
from benchlab.simulation import simulate

__all__ = ["load_run", "load_params", "simulate"]
__version__ = "0.1.0"
