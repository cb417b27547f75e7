"""The live view of a run (`benchlab watch RUN.h5`, `benchlab run ... --watch`): one page on 127.0.0.1.

benchlab/runfile/live.py reads the run file as the writer fills it (read-only, only what is new), decimate.py
keeps the min/max of every channel per bucket of grid rows at every power-of-two size, live.py answers the
page's updates from both, server.py serves the page (static/) and its JSON, launch.py starts it beside a run.
"""
