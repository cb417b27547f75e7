"""`benchlab design`: the next run (and the next sensor) chosen to settle what the runs so far leave open."""
