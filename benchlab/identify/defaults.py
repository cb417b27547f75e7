"""The fitting step when not told otherwise (`benchlab identify --step`; benchlab.identify.data says why 0.5 s).

Light on purpose: the command line's parser reads it for its help; benchlab.identify.data and .api use it.
"""

#: Inputs are averaged over blocks of this many seconds, targets taken at the block starts.
FIT_STEP_S = 0.5
