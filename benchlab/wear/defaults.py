"""The remaining-life Monte Carlo's size when not told otherwise (`benchlab wear --predict/--paths`).

Light on purpose: the command line's parser reads them for its help; benchlab.wear.analysis uses them.
"""

#: Horizon in engagements for the failure probability and the expected wear.
DEFAULT_HORIZON = 10_000
#: Monte Carlo paths of the remaining life.
DEFAULT_PATHS = 500
