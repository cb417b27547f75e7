"""The built-in clutch models' names and what `--model` accepts, in words.

Light on purpose (no numpy): the command line's parser reads MODEL_HELP for its help; benchlab.model.catalog maps
the names to their model files.
"""

#: The paper's clutch models, shipped as models/clutch-NAME.toml.
BUILTIN_NAMES = ("linear", "nonlinear")
MODEL_HELP = f"a model file (TOML, docs/contract.md §6) or a built-in clutch model: {', '.join(BUILTIN_NAMES)}"
