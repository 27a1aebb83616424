"""A plugin module whose import fails: the error must say where the plugin was named."""

raise ValueError("boom")
