"""A module no test may import: a zoo file naming ``tests.plugins.never_imported:Net`` must be refused
without importing it (crowdmpc imports plugins only when a user registers them)."""

raise AssertionError("tests.plugins.never_imported was imported")
