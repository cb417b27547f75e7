"""The `--model` option of the commands that read a parameter file (simulate, report, wear): which model the
file's parameters are for, by default the file's own (contract section 6)."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from benchlab.model.names import MODEL_HELP

if TYPE_CHECKING:
    from benchlab.model.params import ModelParams


def add_model_option(parser: argparse.ArgumentParser) -> None:
    """`--model FILE.toml|linear|nonlinear`, optional."""
    parser.add_argument("--model", help=f"{MODEL_HELP}; default: the parameter file's own model")


def load_model_params(params: str, model: str | None) -> ModelParams:
    """The parameter file, for `--model` where it is given (its parameters must be in the file); imported here so
    that the parser's `add_model_option` costs no numpy."""
    from benchlab.model.catalog import resolve_model
    from benchlab.model.params import load_params

    return load_params(params, resolve_model(model) if model else None)
