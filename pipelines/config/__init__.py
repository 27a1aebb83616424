"""Config files: one TOML file sets the world, the simulator, the scenario, the controller, the MPC and the
``simulate`` / ``sweep`` runs (``crowdmpc --config run.toml simulate``, ``--set mpc.w_coll=1e6``).

* ``schema``: the sections and keys, each mapped onto the frozen dataclass that validates it;
* ``settings``: the dataclasses of the run settings that had none (scenario, controller choice, commands);
* ``entries``: a TOML file and ``--set`` items -> entries, each naming where it came from;
* ``resolve``: the entries -> a validated ``RunConfig``, with one-line errors;
* ``command_line``: a command's ``--config``, ``--set`` and explicit options -> its ``RunConfig``;
* ``render``: a ``RunConfig`` as annotated TOML (``crowdmpc config show``).
"""

from pipelines.config.command_line import Option, command_config, load
from pipelines.config.entries import ConfigError, parse_set, read_file
from pipelines.config.render import render
from pipelines.config.resolve import RunConfig, resolve

__all__ = [
    "ConfigError",
    "Option",
    "RunConfig",
    "command_config",
    "load",
    "parse_set",
    "read_file",
    "render",
    "resolve",
]
