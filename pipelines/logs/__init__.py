"""Episodes as MCAP logs (Foxglove-viewable) and back: schemas, recorder, reader, review, plots.

Imports the closed loop (its outputs are what is written); nothing of the experiments or command line.
"""
