"""A plugin module interrupted while it is imported (Ctrl-C): crowdmpc must let the interrupt through."""

raise KeyboardInterrupt
