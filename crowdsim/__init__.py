"""The crowd world: ORCA pedestrians, multi-robot scenarios, episode metrics. Never imports `mpc`.

Importing it registers the gymnasium environment ``crowdmpc/CrowdNav-v0`` (``crowdsim.gym_env``), as
gymnasium's third-party environments do: ``import crowdsim; gymnasium.make("crowdmpc/CrowdNav-v0")``.
The registration names the class by its import path, so the simulator is loaded by ``make``, not here.
"""

from typing import Final

from gymnasium.envs.registration import register, registry

ENV_ID: Final[str] = "crowdmpc/CrowdNav-v0"

if ENV_ID not in registry:
    register(id=ENV_ID, entry_point="crowdsim.gym_env:CrowdNavEnv")
