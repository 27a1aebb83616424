"""Many episodes: the paper's experiments as cells, sweeps over them, their reports, calibration runs.

Imports the closed loop and the logs; nothing of the command line.
"""
