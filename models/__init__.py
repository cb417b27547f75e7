"""Model files shipped with benchlab (TOML, contract section 6): the paper's clutch models.

`benchlab --model linear|nonlinear` are names for clutch-linear.toml and clutch-nonlinear.toml
(benchlab.model.catalog); this package only makes pip install them beside the code.
"""
