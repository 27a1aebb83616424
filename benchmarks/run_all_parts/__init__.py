"""benchmarks/run_all.py's parts: the measurements it takes (``measurements``) and the sections that take
them over the sizes asked for (``sections``). Not scripts: they import the sibling benchmark modules
(sweep_floor.py, orca_step.py, ...) by name, from the folder run_all.py puts on ``sys.path``."""
