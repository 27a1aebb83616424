"""What the loop's callers hand ``run_episodes``, ``run_episode`` and ``run_gym_episode`` besides the
controller and its meta (pipelines.loop.contract): counts, seed, sensor, observers and the simulator's
config, each refused in one line naming the argument before anything is built or run."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from crowdsim.env_config import EnvConfig
from crowdsim.world import is_sensor_range
from pipelines.errors import PipelineError
from pipelines.loop.spec import ControllerSpec
from predictors.errors import short_repr


def check_run(
    spec: Any,
    episodes: Any,
    seed: Any,
    env_config: Any,
    sensor_range: Any,
    sensor_tracks: Any,
    into: Any = None,
    observers_factory: Any = None,
) -> int:
    """``run_episodes``' arguments, before the controller is built, and with no episode to run too (seed "0"
    failed at seed + i, None likewise, and True ran seed 1); numpy integers are taken, as a notebook's counts
    often come from numpy, and the seed returned as a Python int (numpy's wrapped round past its largest).
    ``into`` and ``observers_factory`` failed after the first episode (its result lost) or at it."""
    if not isinstance(spec, ControllerSpec):
        raise PipelineError(
            f"run_episodes takes a ControllerSpec (e.g. ControllerSpec('cmpc')) and builds the controller, "
            f"got {short_repr(spec)}"
        )
    for name, value in (("episodes", episodes), ("seed", seed)):
        if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 0:
            raise PipelineError(f"run_episodes: {name} must be an int >= 0, got {short_repr(value)}")
    _check_env_config(env_config, "run_episodes")
    # named here, before the build: a bad one was refused after it, as the margins' or RangeLimited's radius
    sensed = sensor_range.item() if isinstance(sensor_range, np.generic) else sensor_range
    if sensed is not None and not is_sensor_range(sensed):
        raise PipelineError(
            "run_episodes: sensor_range must be a finite number of metres > 0 (None: every human seen), got "
            f"{short_repr(sensor_range)}"
        )
    if sensor_range is None and sensor_tracks is not True:  # simulate refuses --no-sensor-tracks alone too
        raise PipelineError(
            f"run_episodes: sensor_tracks={short_repr(sensor_tracks)} is a sensor's setting; give "
            "sensor_range too (metres)"
        )
    if into is not None and not callable(getattr(into, "append", None)):
        raise PipelineError(
            f"run_episodes: into must be a list the results are appended to, got {short_repr(into)}"
        )
    if observers_factory is not None and not callable(observers_factory):
        raise PipelineError(
            "run_episodes: observers_factory must be a function returning each episode's observers (e.g. "
            f"lambda: [recorder]), got {short_repr(observers_factory)}"
        )
    return int(seed)


def checked_observers(observers: Any, env_config: Any, where: str) -> tuple[Any, ...]:
    """``observers`` as a tuple of objects with ``on_reset``, ``on_step`` and ``on_end``, and ``env_config``
    an EnvConfig; PipelineError naming the argument otherwise (an AttributeError came from inside)."""
    _check_env_config(env_config, where)
    if (
        observers is None
        or isinstance(observers, str | bytes | Mapping)
        or not hasattr(observers, "__iter__")
    ):
        raise PipelineError(
            f"{where}: observers must be a sequence of EpisodeObservers, got {short_repr(observers)}"
        )
    observers = tuple(observers)
    for observer in observers:
        if not all(callable(getattr(observer, hook, None)) for hook in ("on_reset", "on_step", "on_end")):
            raise PipelineError(
                f"{where}: observer {short_repr(observer)} has no on_reset, on_step and on_end (an "
                "EpisodeObserver, pipelines.loop.episode)"
            )
    return observers


def _check_env_config(env_config: Any, where: str) -> None:
    if not isinstance(env_config, EnvConfig):
        raise PipelineError(f"{where}: env_config must be an EnvConfig, got {short_repr(env_config)}")
