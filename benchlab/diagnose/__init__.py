"""Show what the model gets wrong, name the cause, extend the model, measure the gain."""

from benchlab.diagnose.report import diagnose

__all__ = ["diagnose"]
