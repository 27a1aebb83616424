"""The crowd world: ORCA pedestrians, multi-robot scenarios, episode metrics. Never imports `mpc`.

Importing it registers the gymnasium environment ``crowdmpc/CrowdNav-v0`` (``crowdsim.gym_env``), as
gymnasium's third-party environments do: ``import crowdsim; gymnasium.make("crowdmpc/CrowdNav-v0")``.
The registration names the class by its import path, so the simulator is loaded by ``make``, not here.
"""

from typing import Final

from gymnasium.envs.registration import register, registry

ENV_ID: Final[str] = "crowdmpc/CrowdNav-v0"

if ENV_ID not in registry:
    # Without gymnasium's passive checker (gym.make's default wraps every env in it): in gymnasium 1.4 a first
    # reset that raises (a layout with a typo) left it holding None, and every later step on that env raised
    # "TypeError: cannot unpack non-iterable NoneType object" however right the next layout was. The tests run
    # gymnasium's full check_env on the environment instead; gym.make(..., disable_env_checker=False) asks
    # for the checker all the same.
    register(id=ENV_ID, entry_point="crowdsim.gym_env:CrowdNavEnv", disable_env_checker=True)
