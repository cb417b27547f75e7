"""Wear prediction from the estimated lining temperatures (paper section III.A, eq. 1-3)."""

from benchlab.wear.analysis import WearReport, analyse_wear
from benchlab.wear.clutchfile import ClutchSpec, default_clutch, load_clutch
from benchlab.wear.state import WearState

__all__ = ["ClutchSpec", "WearReport", "WearState", "analyse_wear", "default_clutch", "load_clutch"]
