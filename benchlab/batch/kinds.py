"""What a batch can do with each run, and the model each kind uses when `--model` is not given.

Light on purpose: the command line's parser reads KINDS for its choices; benchlab.batch.tasks runs each kind.
"""

KINDS = ("identify", "diagnose", "wear")
#: `--model` when not given: identify and wear fit the paper's nonlinear model; diagnose starts from the
#: linear one (its own default: the paper's starting point).
DEFAULT_MODEL = {"identify": "nonlinear", "wear": "nonlinear", "diagnose": "linear"}
