"""Measurements from other tools into run files: the mapping file (`mapping.py`), the grid rules (`grid.py`) and
MDF files (`mdf.py`). `benchlab import` (benchlab/commands/import_csv.py) reads CSV itself and MDF through here."""
