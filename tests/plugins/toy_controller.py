"""A user's controller as a plugin: ``crowdmpc --plugin tests.plugins.toy_controller:StraightLine simulate
--controller tests.plugins.toy_controller:StraightLine``.

Every robot heads straight for its goal at a constant ``speed`` (m/s), blind to everyone else, and stops on
it: the commanded velocity is ``speed`` towards the goal, or the whole remaining offset in one step when that
is shorter; the acceleration that reaches it in one step is clipped to the bound.
"""

from __future__ import annotations

import dataclasses
import os
import time
from typing import Any

import numpy as np

from crowdsim.control import ControlOutput
from crowdsim.env import EnvConfig, Observation
from crowdsim.world import A_MAX


class StraightLine:
    uses_predictor = False  # the controller's facts (pipelines.loop.spec); both default to False
    compiles = False

    name = "straight_line"
    predictor = None

    def __init__(self, spec: Any, env_config: EnvConfig | None, *, jit: bool = False, speed: float = 0.8):
        self.a_max = A_MAX if env_config is None else env_config.a_max  # m/s^2, per component
        self.speed = speed  # m/s

    def reset(self, obs: Observation) -> None:
        pass

    def act(self, obs: Observation) -> ControlOutput:
        started = time.perf_counter()
        offset = obs.robot_goals - obs.robot_positions
        dist = np.linalg.norm(offset, axis=1, keepdims=True)
        wanted = offset / np.maximum(dist, 1e-9) * np.minimum(self.speed, dist / obs.dt)
        a = np.clip((wanted - obs.robot_velocities) / obs.dt, -self.a_max, self.a_max)
        return ControlOutput(accelerations=a, solve_time_s=time.perf_counter() - started)

    def describe(self) -> dict[str, Any]:
        return {"predictor_sha256": None, "config": {"speed": self.speed}}

    def close(self) -> None:
        pass


class StderrNoise(StraightLine):
    """Writes on descriptors 1 and 2 at each step, below Python, as a C library's messages (CasADi's on
    std::cout and std::cerr) or a child process's do."""

    NOISE = b"toy controller: a C library's warning\n"

    def act(self, obs: Observation) -> ControlOutput:
        for fd in (1, 2):
            os.write(fd, self.NOISE)
        return super().act(obs)


class NoAct:
    """Not a controller: ``--plugin`` refuses it in one line."""

    name = "no_act"

    def reset(self, obs: Observation) -> None:
        pass


class BadFacts(StraightLine):
    """States a fact that is no bool: refused when registered."""

    uses_predictor = "yes"  # type: ignore[assignment]


class Broken(StraightLine):
    """Refuses to be built, as a plugin validating its options would."""

    def __init__(self, spec: Any, env_config: EnvConfig | None, *, jit: bool = False):
        super().__init__(spec, env_config, jit=jit, speed=-1.0)
        raise ValueError(f"speed must be a positive number of m/s, got {self.speed}")


class Nameless(StraightLine):
    """Builds an object without a name: make_controller refuses it."""

    name = ""


class NamedCmpc(StraightLine):
    """Builds an object named as the shipped CMPC: make_controller refuses it."""

    name = "cmpc"


class Predicting(StraightLine):
    """Plans with the run's predictor (``uses_predictor``), as the guide says: names ``spec.predictor``."""

    uses_predictor = True
    name = "predicting"

    def __init__(self, spec: Any, env_config: EnvConfig | None, *, jit: bool = False):
        super().__init__(spec, env_config, jit=jit)
        self.predictor = spec.predictor


class LoadingItsPredictor(Predicting):
    """Loads the run's predictor itself, as the guide says (``predictors.registry.load_predictor``), and says
    which weights it planned with."""

    name = "loading_its_predictor"

    def __init__(self, spec: Any, env_config: EnvConfig | None, *, jit: bool = False):
        from predictors.registry import load_predictor, loaded_sha256

        super().__init__(spec, env_config, jit=jit)
        self.model = load_predictor(spec.predictor)
        self.weights_sha256 = loaded_sha256(self.model)

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "predictor_sha256": self.weights_sha256}


class PredictingItsOwn(Predicting):
    """Names a predictor of its own, whatever the run asks for: the records and the cell keys disagreed."""

    name = "predicting_its_own"

    def __init__(self, spec: Any, env_config: EnvConfig | None, *, jit: bool = False):
        super().__init__(spec, env_config, jit=jit)
        self.predictor = "orca_oracle"


class PredictingNone(Predicting):
    """States ``uses_predictor`` and names none."""

    name = "predicting_none"

    def __init__(self, spec: Any, env_config: EnvConfig | None, *, jit: bool = False):
        super().__init__(spec, env_config, jit=jit)
        self.predictor = None


class HiddenPredictor(StraightLine):
    """Names a predictor while stating it uses none (the cell keys say none)."""

    name = "hidden_predictor"
    predictor = "constant_velocity"  # type: ignore[assignment]


class SwapGoals(StraightLine):
    """Heads each robot for the goal of the robot at the other end of the team (robot ``i`` for goal
    ``M - 1 - i``): two robots side by side cross each other's path halfway, blind to each other, and touch
    (robot-robot contact); none reaches its own goal."""

    name = "swap_goals"

    def act(self, obs: Observation) -> ControlOutput:
        return super().act(dataclasses.replace(obs, robot_goals=obs.robot_goals[::-1]))


class Logged(StraightLine):
    """Writes "init PID" when built and "close PID" when closed to the file $CROWDMPC_TEST_CLOSE_LOG names."""

    def __init__(self, spec: Any, env_config: EnvConfig | None, *, jit: bool = False):
        super().__init__(spec, env_config, jit=jit)
        self._write("init")

    def _write(self, what: str) -> None:
        with open(os.environ["CROWDMPC_TEST_CLOSE_LOG"], "a", encoding="utf-8") as log:
            log.write(f"{what} {os.getpid()}\n")

    def close(self) -> None:
        self._write("close")


class CloseRaises(StraightLine):
    def close(self) -> None:
        raise OSError("the serial port is gone")


class WrappedMPC(StraightLine):
    """A controller of one's own around the shipped CMPC with d_min 1.0 m, which leaves the row of 3 no room
    at its goals 1.0 m apart: the MPC's warning on the layout is the user's only word on it (simulate's and
    sweep's notes are for cmpc and dmpc)."""

    name = "wrapped_mpc"

    def __init__(self, spec: Any, env_config: EnvConfig | None, *, jit: bool = False):
        from pipelines.loop.controllers import ControllerSpec, make_controller

        inner = ControllerSpec("cmpc", "constant_velocity", mpc_overrides=(("d_min", 1.0),))
        self.inner = make_controller(inner, env_config, jit=jit)

    def reset(self, obs: Observation) -> None:
        self.inner.reset(obs)

    def act(self, obs: Observation) -> ControlOutput:
        return self.inner.act(obs)

    def describe(self) -> dict[str, Any]:
        return {"predictor_sha256": None, "config": {"d_min": 1.0}}

    def close(self) -> None:
        self.inner.close()


class Hang(StraightLine):
    """A step that never returns (a plugin's deadlock): writes the file $CROWDMPC_TEST_HANG names, then
    sleeps."""

    name = "hang"

    def act(self, obs: Observation) -> ControlOutput:
        with open(os.environ["CROWDMPC_TEST_HANG"], "w", encoding="utf-8") as marker:
            marker.write("stepping")
        time.sleep(1000)
        return super().act(obs)
