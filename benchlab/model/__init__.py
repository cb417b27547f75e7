"""Models as data: model files (contract section 6) parsed, checked, compiled into thermal networks, written.

`expressions` compiles the laws (a whitelisting parser, never `eval`), `definition` reads, checks and writes
model files, `build` turns one into a ThermalNetwork and a ModelSpec, `catalog` resolves `--model`.
"""
