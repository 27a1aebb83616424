"""What a controller is handed, checked before it plans: one finite row per agent in each of an
observation's current fields, and its clock (``check_fields``; the MPC checks its history too,
pipelines.loop.mpc_setup, and how large the numbers are, ``check_magnitudes``)."""

from __future__ import annotations

import math

import numpy as np

from crowdsim.env import Observation
from mpc.step_data import MAX_MAGNITUDE
from pipelines.errors import PipelineError
from predictors.errors import short_repr


def check_fields(obs: Observation) -> None:
    """PipelineError naming the first of the robots' and humans' fields that is not one row per agent: a
    one-robot ``robot_reached`` for three robots was stretched to all three (each taken as arrived), other
    shapes failed in numpy's words."""
    m, n = (_agents(obs, name) for name in ("robot_positions", "human_positions"))
    radius = obs.radius
    try:
        value = math.nan if isinstance(radius, bool | str | bytes) else float(radius)  # a 0-d array too
    except (TypeError, ValueError):
        value = math.nan
    if not 0 < value < math.inf:  # NaN passed, and every robot counted as off its goal for good
        raise PipelineError(f"obs.radius must be a number of metres > 0 (a robot's arrival), got {radius!r}")
    _check_clock(obs)
    for name, shape in (
        ("robot_positions", (m, 2)),
        ("robot_velocities", (m, 2)),
        ("robot_goals", (m, 2)),
        ("robot_last_actions", (m, 2)),
        ("robot_reached", (m,)),
        ("human_positions", (n, 2)),
        ("human_velocities", (n, 2)),
    ):
        got = np.shape(getattr(obs, name))
        if got != shape:
            agents = "robot of obs.robot_positions" if name.startswith("robot") else "human"
            raise PipelineError(f"obs.{name} has shape {got}, expected {shape}: one row per {agents}")
        # positions: check_positions; the humans' velocities only ORCA (and its oracle) read: check_state
        if name in ("robot_reached", "robot_positions", "human_positions", "human_velocities"):
            continue
        # NaN velocities failed in the MPC as "states must be finite ... (M, 4)"
        _check_finite(obs, name, "a controller plans from the current state")
    _check_present(obs)
    _check_reached(obs)


def _agents(obs: Observation, name: str) -> int:
    """The rows of positions field ``name``, else a PipelineError: ``n_robots`` and ``n_humans`` are its
    ``len``, and None given for "no humans" failed in it as a TypeError."""
    value = getattr(obs, name)
    try:
        shape = np.shape(value)
    except ValueError:  # rows of different lengths
        shape = (-1,)
    if len(shape) != 2 or shape[1] != 2:
        got = "rows of different lengths" if shape == (-1,) else f"shape {shape}: {short_repr(value)}"
        raise PipelineError(
            f"obs.{name} must be an (n, 2) array of positions in metres (np.zeros((0, 2)) for none), "
            f"got {got}"
        )
    return shape[0]


def _check_clock(obs: Observation) -> None:
    """PipelineError where ``obs.step`` is not an int >= 0 or ``obs.time`` not a finite number of seconds
    >= 0. The step is read: with ``human_observed`` None every human counts as seen ``step + 1`` times (the
    per-class margins' "new"), a sensor counts its tracks from it, and a recording stamps it: -1 or 2.5 were
    taken as they came (a track of 0 or 3.5 positions), NaN failed later in the recorder's ``int``."""
    step, time = obs.step, obs.time
    if isinstance(step, bool) or not isinstance(step, int | np.integer) or step < 0:
        raise PipelineError(
            f"obs.step must be an int >= 0 (control periods since the episode began; with obs.human_observed "
            f"None every human counts as seen step + 1 times), got {step!r}"
        )
    if isinstance(time, bool) or not isinstance(time, int | float | np.integer | np.floating):
        value = math.nan
    else:
        value = float(time)
    if not 0 <= value < math.inf:
        raise PipelineError(
            f"obs.time must be a finite number of seconds >= 0 since the episode began, got {time!r}"
        )


def _check_present(obs: Observation) -> None:
    """PipelineError where ``obs.human_present`` is given and is not one boolean per human: two Trues for
    four humans passed as every human tracked, and 0.5 as tracked."""
    if obs.human_present is None:
        return
    present = np.asarray(obs.human_present)
    if present.shape != (obs.n_humans,) or not _is_flags(present):
        raise PipelineError(
            f"obs.human_present must be {obs.n_humans} boolean{'' if obs.n_humans == 1 else 's'}, one per "
            "human (tracked now or not), got "
            f"{present.dtype} of shape {present.shape}"
            + ("" if present.shape != (obs.n_humans,) else f": {present.tolist()}")
        )


def _is_flags(values: np.ndarray) -> bool:
    """Booleans, or numbers that are each 0 or 1 (a tracker's or a hand-built array of ints)."""
    return values.dtype == bool or (values.dtype.kind in "iuf" and bool(np.isin(values, (0, 1)).all()))


def _check_reached(obs: Observation) -> None:
    """PipelineError where ``obs.robot_reached`` (its shape checked) is not booleans or 0/1: the MPC took
    ``bool`` of each, so 0.5 or 2 (a distance, a count) read as arrived, and that robot held position."""
    reached = np.asarray(obs.robot_reached)
    if not _is_flags(reached):
        raise PipelineError(
            "obs.robot_reached must be one boolean per robot (has it been within obs.radius of its goal), "
            f"got {reached.dtype}: {short_repr(reached.tolist())}"
        )


def _check_finite(obs: Observation, name: str, why: str) -> None:
    """PipelineError naming the first row of field ``name`` that is not finite, and ``why`` it matters."""
    values = np.asarray(getattr(obs, name))
    finite = np.isfinite(values.astype(float)).all(axis=1)
    if not finite.all():
        row = int(np.flatnonzero(~finite)[0])
        raise PipelineError(
            f"obs.{name} holds a value that is not finite (row {row}: {values[row].tolist()}); {why}"
        )


def check_positions(obs: Observation) -> None:
    """PipelineError naming the first agent whose current position is not finite."""
    now = np.concatenate([obs.robot_positions, obs.human_positions]).astype(float)
    lost = ~np.isfinite(now).all(axis=1)
    if lost.any():
        i = int(np.flatnonzero(lost)[0])
        who, field = agent(obs, i)
        raise PipelineError(
            f"{field} holds a position that is not finite ({who} at {now[i].tolist()}); a controller plans "
            "from every agent's current position (hand it only the people tracked now)"
        )


def check_magnitudes(obs: Observation) -> None:
    """PipelineError naming the first of the current fields the MPC plans from that holds a number beyond
    ``mpc.step_data.MAX_MAGNITUDE``: a robot velocity of 1e200, finite, made the NLP's gradient NaN and the
    first Fatrop solve never returned (or the MPC refused it in StepData's words, not the observation's);
    then the history (``obs.history``, of its shape), which the predictor reads."""
    for name, unit in (
        ("robot_positions", "m"),
        ("robot_velocities", "m/s"),
        ("robot_goals", "m"),
        ("robot_last_actions", "m/s^2"),
        ("human_positions", "m"),
    ):
        values = np.asarray(getattr(obs, name), dtype=float)
        beyond = ~np.all(np.abs(values) <= MAX_MAGNITUDE, axis=1)
        if beyond.any():
            row = int(np.flatnonzero(beyond)[0])
            raise PipelineError(
                f"obs.{name} holds a number beyond {MAX_MAGNITUDE:g} {unit} in magnitude (row {row}: "
                f"{values[row].tolist()}), the most the MPC plans with; far larger ones overflow its "
                "arithmetic"
            )
    history = np.asarray(obs.history, dtype=float)
    # a human at 1e307 a step ago: the coupled NLP's predictor (coupling nlp) ran the humans to 1e308, its
    # gradient was NaN and the Fatrop solve never returned (a NaN, a step not observed, is no number beyond)
    beyond = np.abs(history) > MAX_MAGNITUDE
    if beyond.any():
        step, i = (int(k) for k in np.argwhere(beyond)[0][:2])
        raise PipelineError(
            f"obs.history holds a number beyond {MAX_MAGNITUDE:g} m in magnitude ({agent(obs, i)[0]} at row "
            f"{step - len(history)}: {history[step, i].tolist()}), the most the MPC plans with; far larger "
            "ones overflow its arithmetic"
        )


def agent(obs: Observation, i: int) -> tuple[str, str]:
    """Agent ``i`` of the history's columns (robots, then humans) and the field that holds its position."""
    if i < obs.n_robots:
        return f"robot {i}", "obs.robot_positions"
    return f"human {i - obs.n_robots}", "obs.human_positions"


def check_state(obs: Observation) -> None:
    """``check_fields`` and ``check_positions`` of an observation a controller without a history acts on
    (ORCA, the straight line): NaN positions handed to them gave NaN accelerations, or humans planned around
    as if absent, where the MPC refused them."""
    check_fields(obs)
    check_positions(obs)
    _check_finite(obs, "human_velocities", "ORCA plans with the humans' velocities")
