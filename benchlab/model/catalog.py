"""The built-in model names and the `--model FILE|linear|nonlinear` argument.

`linear` and `nonlinear` name the paper's clutch models, shipped as model files in `models/`; there is no
other definition of them. A model is read and checked once per file and process.
"""

from __future__ import annotations

import os
from dataclasses import replace
from functools import lru_cache
from pathlib import Path

import models
from benchlab.errors import InputError
from benchlab.identify.spec import ModelSpec
from benchlab.model.build import build_spec
from benchlab.model.definition import ModelDefinition, load_model
from benchlab.model.names import BUILTIN_NAMES

MODELS_DIR = Path(models.__file__).resolve().parent
BUILTIN = {name: MODELS_DIR / f"clutch-{name}.toml" for name in BUILTIN_NAMES}


@lru_cache(maxsize=None)
def _builtin(name: str) -> ModelDefinition:
    return replace(load_model(BUILTIN[name]), alias=name)


def builtin(name: str) -> ModelDefinition:
    """The built-in clutch model `linear` or `nonlinear`."""
    if name not in BUILTIN:
        raise InputError("--model", name, f"a model file or one of {', '.join(BUILTIN)}")
    return _builtin(name)


def resolve_model(text: "str | os.PathLike[str]", option: str = "--model") -> ModelDefinition:
    """A built-in name or a model file path; bad input names the option or the file."""
    text = str(text)
    if text in BUILTIN:
        return builtin(text)
    if not text.endswith(".toml") and not Path(text).exists():
        raise InputError(option, text, f"a model file (.toml) or one of {', '.join(BUILTIN)}")
    return load_model(text)


def model_spec(model: "str | ModelDefinition") -> ModelSpec:
    """What identification fits for a model (a name, a path or a checked definition)."""
    return build_spec(model if isinstance(model, ModelDefinition) else resolve_model(model))
