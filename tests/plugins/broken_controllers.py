"""Controller plugins that break the documented contract (docs/extending.md, section 6), each in one way:
``act`` returns the bare accelerations (an ndarray) instead of a ``ControlOutput``, or a ``ControlOutput``
with a field of the wrong shape or type; ``describe`` returns no dict. Registered as
``tests.plugins.broken_controllers:ArrayAct`` and so on."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from crowdsim.control import ControlOutput
from crowdsim.env import Observation
from tests.plugins.toy_controller import StraightLine


class ArrayAct(StraightLine):
    name = "array_act"

    def act(self, obs: Observation) -> np.ndarray:  # type: ignore[override]
        return super().act(obs).accelerations


class TooFewRows(StraightLine):
    """Accelerations for all robots but the last."""

    name = "too_few_rows"

    def act(self, obs: Observation) -> ControlOutput:
        out = super().act(obs)
        return dataclasses.replace(out, accelerations=out.accelerations[:-1])


class ExtraRow(StraightLine):
    """One row of accelerations too many."""

    name = "extra_row"

    def act(self, obs: Observation) -> ControlOutput:
        out = super().act(obs)
        return dataclasses.replace(out, accelerations=np.vstack([out.accelerations, [[0.5, 0.5]]]))


class FlatPlan(StraightLine):
    name = "flat_plan"

    def act(self, obs: Observation) -> ControlOutput:
        return dataclasses.replace(super().act(obs), plan=np.zeros(5))


class PredictionOfRobots(StraightLine):
    """A prediction with a row per robot, not per human."""

    name = "prediction_of_robots"

    def act(self, obs: Observation) -> ControlOutput:
        return dataclasses.replace(super().act(obs), prediction=np.zeros((4, obs.n_robots, 2)))


class IterationsNone(StraightLine):
    name = "iterations_none"

    def act(self, obs: Observation) -> ControlOutput:
        return dataclasses.replace(super().act(obs), iterations=None)  # type: ignore[arg-type]


class StatusNone(StraightLine):
    name = "status_none"

    def act(self, obs: Observation) -> ControlOutput:
        return dataclasses.replace(super().act(obs), status=None)  # type: ignore[arg-type]


class DescribeNone(StraightLine):
    name = "describe_none"

    def describe(self) -> dict[str, Any]:
        return None  # type: ignore[return-value]


class ConfigList(StraightLine):
    name = "config_list"

    def describe(self) -> dict[str, Any]:
        return {"config": [1, 2]}


class SeedInDescribe(StraightLine):
    name = "seed_in_describe"

    def describe(self) -> dict[str, Any]:
        return {"seed": 0, "predictor_sha256": None, "config": {}}


class FallbackNumber(StraightLine):
    name = "fallback_number"

    def act(self, obs: Observation) -> ControlOutput:
        return dataclasses.replace(super().act(obs), fallback=3)  # type: ignore[arg-type]


class SolveTimeNone(StraightLine):
    name = "solve_time_none"

    def act(self, obs: Observation) -> ControlOutput:
        return dataclasses.replace(super().act(obs), solve_time_s=None)  # type: ignore[arg-type]


class PotentialText(StraightLine):
    name = "potential_text"

    def act(self, obs: Observation) -> ControlOutput:
        return dataclasses.replace(super().act(obs), potential="x")  # type: ignore[arg-type]


class ExtraList(StraightLine):
    """extra as a list: recorded against /mpc/solver's schema (an object), which review --check refused."""

    name = "extra_list"

    def act(self, obs: Observation) -> ControlOutput:
        return dataclasses.replace(super().act(obs), extra=[1, 2])  # type: ignore[arg-type]


class ObjectInExtra(StraightLine):
    """A value JSON cannot hold: the recorder's error, naming no controller."""

    name = "object_in_extra"

    def act(self, obs: Observation) -> ControlOutput:
        return dataclasses.replace(super().act(obs), extra={"x": object()})


class IterationText(StraightLine):
    """An iteration's prediction as text: a traceback from the recorder under --record-iterations."""

    name = "iteration_text"

    def act(self, obs: Observation) -> ControlOutput:
        return dataclasses.replace(super().act(obs), iteration_predictions=("a",))  # type: ignore[arg-type]


class IterationOfRobots(StraightLine):
    """An iteration's prediction with a row per robot, not per human."""

    name = "iteration_of_robots"

    def act(self, obs: Observation) -> ControlOutput:
        prediction = np.zeros((4, obs.n_robots, 2))
        return dataclasses.replace(super().act(obs), iteration_predictions=(prediction,))


class EnvInConfig(StraightLine):
    """describe()["config"]["env"] replaced the simulator's settings in recordings' and records' config."""

    name = "env_in_config"

    def describe(self) -> dict[str, Any]:
        return {"predictor_sha256": None, "config": {"env": {"dt": 99.0}}}


class RowsAsLists(StraightLine):
    """Accelerations as a list of rows: a valid array, which the recorder could not .tolist()."""

    name = "rows_as_lists"

    def act(self, obs: Observation) -> ControlOutput:
        out = super().act(obs)
        return dataclasses.replace(out, accelerations=np.asarray(out.accelerations).tolist())


class BoolAccelerations(StraightLine):
    """Whether each component is positive: True was taken for 1 m/s^2."""

    name = "bool_accelerations"

    def act(self, obs: Observation) -> ControlOutput:
        out = super().act(obs)
        return dataclasses.replace(out, accelerations=out.accelerations > 0)


class NaNAccelerations(StraightLine):
    name = "nan_accelerations"

    def act(self, obs: Observation) -> ControlOutput:
        out = super().act(obs)
        return dataclasses.replace(out, accelerations=np.full_like(out.accelerations, np.nan))


class InfPlan(StraightLine):
    name = "inf_plan"

    def act(self, obs: Observation) -> ControlOutput:
        plan = np.zeros((obs.n_robots, 4, 2))
        plan[0, 1, 0] = np.inf
        return dataclasses.replace(super().act(obs), plan=plan)


class NaNPrediction(StraightLine):
    """One coordinate NaN: a human all NaN is one not predicted (out of view), this one is broken."""

    name = "nan_prediction"

    def act(self, obs: Observation) -> ControlOutput:
        prediction = np.zeros((4, obs.n_humans, 2))
        prediction[0, 0, 1] = np.nan
        return dataclasses.replace(super().act(obs), prediction=prediction)


class NegativeSolveTime(StraightLine):
    """A solve time of -5 s: the summary printed a median of -5000 ms."""

    name = "negative_solve_time"

    def act(self, obs: Observation) -> ControlOutput:
        return dataclasses.replace(super().act(obs), solve_time_s=-5.0)


class NaNSolveTime(StraightLine):
    name = "nan_solve_time"

    def act(self, obs: Observation) -> ControlOutput:
        return dataclasses.replace(super().act(obs), solve_time_s=float("nan"))


class NegativeIterations(StraightLine):
    name = "negative_iterations"

    def act(self, obs: Observation) -> ControlOutput:
        return dataclasses.replace(super().act(obs), iterations=-1)


class BoolIterations(StraightLine):
    """``a > 0`` for a count: a bool is an int to Python, not a number of iterations."""

    name = "bool_iterations"

    def act(self, obs: Observation) -> ControlOutput:
        return dataclasses.replace(super().act(obs), iterations=True)


class BoolSolveTime(StraightLine):
    name = "bool_solve_time"

    def act(self, obs: Observation) -> ControlOutput:
        return dataclasses.replace(super().act(obs), solve_time_s=False)


class HugeIterations(StraightLine):
    """A count no float holds: checking it as a number overflowed into a traceback."""

    name = "huge_iterations"

    def act(self, obs: Observation) -> ControlOutput:
        return dataclasses.replace(super().act(obs), iterations=10**400)


class OwnFallback(StraightLine):
    """Falls back its own way, and says so by its own name."""

    name = "own_fallback"

    def act(self, obs: Observation) -> ControlOutput:
        return dataclasses.replace(super().act(obs), fallback="stop")


class ObjectInConfig(StraightLine):
    """A config value no JSON holds: simulate stringified it into the MCAP, a sweep refused the episode."""

    name = "object_in_config"

    def describe(self) -> dict[str, Any]:
        return {"predictor_sha256": None, "config": {"speed": object()}}


class NumberSha256(StraightLine):
    name = "number_sha256"

    def describe(self) -> dict[str, Any]:
        return {"predictor_sha256": 123, "config": {}}


def centre_in_place(obs: Observation) -> None:
    """The scene centred on the first robot, in place, as research code does (``positions -= centre``)."""
    centre = obs.robot_positions[0].copy()
    for positions in (obs.robot_positions, obs.robot_goals, obs.human_positions, obs.human_goals):
        positions -= centre
    obs.history[...] -= centre


class CentresInPlace(StraightLine):
    """Centres its observation in place (``centre_in_place``) in reset and in act. The recorder was handed
    the same observation: the recordings' positions moved with it."""

    name = "centres_in_place"

    def reset(self, obs: Observation) -> None:
        centre_in_place(obs)

    def act(self, obs: Observation) -> ControlOutput:
        out = super().act(obs)  # from the true positions: the episode itself is the straight line's
        centre_in_place(obs)
        return out


class EmptyPlan(StraightLine):
    """A plan and a prediction of no steps (H = 0), for "nothing planned": written into the recording as
    positions of shape (0,), which review --check refused and review --plot crashed on (numpy's concatenate
    error). None says "no plan"."""

    name = "empty_plan"

    def act(self, obs: Observation) -> ControlOutput:
        return dataclasses.replace(super().act(obs), plan=np.zeros((obs.n_robots, 0, 2)))


class EmptyPrediction(StraightLine):
    name = "empty_prediction"

    def act(self, obs: Observation) -> ControlOutput:
        return dataclasses.replace(super().act(obs), prediction=np.zeros((0, obs.n_humans, 2)))
