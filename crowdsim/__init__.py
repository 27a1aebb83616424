"""The crowd world: ORCA pedestrians, multi-robot scenarios, episode metrics. Never imports `mpc`."""
