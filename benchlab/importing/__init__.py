"""Measurements from other tools into run files: the mapping file (`mapping.py`), the grid rules (`grid.py`), MDF
files (`mdf.py`), CAN logs with a DBC (`canlog.py`), and several inputs merged on one clock and grid with their raw
streams (`sources.py`). `benchlab import` (benchlab/commands/import_csv.py) reads CSV itself and the rest through
here."""
