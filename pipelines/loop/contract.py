"""What the closed loop takes from a controller (docs/extending.md, section 6) and from its caller's meta,
checked in one place for ``run_episode`` and ``run_gym_episode``.

A plugin that breaks the contract is a one-line PipelineError naming it, raised where the loop receives the
value: left alone, a wrong value surfaced as a traceback from the simulator, the loop's bookkeeping or the
MCAP recorder steps later, or (padded into the gym action) as a robot that silently never moved.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Mapping
from numbers import Real
from typing import Any, Final

import numpy as np

from crowdsim.control import ControlOutput
from crowdsim.env import Observation
from crowdsim.env_config import EnvConfig
from crowdsim.observation import array_copies
from pipelines.errors import PipelineError, interrupt_behind
from pipelines.loop.controllers import Controller
from pipelines.plain_json import plain
from predictors.errors import short_repr

# The meta every episode gets from the loop itself. A caller's meta that set one would relabel every episode
# alike: recordings are named by seed and scenario, so a run's episodes would overwrite one file.
OWN_FIELDS: Final[tuple[str, ...]] = (
    "seed",
    "scenario",
    "n_humans",
    "n_robots",
    "controller",
    "predictor",
    "predictor_sha256",
    "config",
    "end_on_collision",  # whether a contact ends the episode: review's "ended" (pipelines.logs.ending)
)


# The modules of the shipped controllers' classes: what one of them raises is a bug, kept with its traceback.
# RangeLimited (sensing) calls the controller it wraps through ``called`` itself: what reaches the loop from
# it is a plugin's PipelineError already, or a shipped controller's bug.
SHIPPED_MODULES: Final[frozenset[str]] = frozenset(
    {"pipelines.loop.baselines", "pipelines.loop.mpc", "pipelines.loop.sensing"}
)


def _named(controller: Controller) -> str:
    return f"controller {controller.name!r} ({type(controller).__qualname__})"


def called(controller: Controller, method: str, *args: Any) -> Any:
    """``controller.<method>(*args)``. What a plugin's method raises is a one-line PipelineError naming the
    controller and the method (its traceback kept as the cause, for a sweep's errors.jsonl); a shipped
    controller's exception, a PipelineError and a Ctrl-C (also one CasADi wrapped) propagate as they are."""
    try:
        return getattr(controller, method)(*args)
    except PipelineError:
        raise
    except Exception as exc:
        if type(controller).__module__ in SHIPPED_MODULES or interrupt_behind(exc) is not None:
            raise
        raise PipelineError(f"{_named(controller)}: {method}() raised {type(exc).__name__}: {exc}") from exc


def handed_out(obs: Observation) -> Observation:
    """``obs`` with copies of its arrays: what the loops hand a controller's ``reset`` and ``act``. The loops
    hand the observation itself to their observers after ``act``, and a controller that changed its arrays in
    place (the scene centred on a robot, ``obs.human_positions -= centre``) moved the positions the recorder
    then wrote, while the metrics, from the simulator, stayed right."""
    return dataclasses.replace(obs, **array_copies(obs))


def _check_array(
    controller: Controller,
    field: str,
    value: object,
    shape: tuple[int | None, ...],
    expected: str,
    *,
    humans_axis: int | None = None,
) -> None:
    """PipelineError unless ``value`` is an array of finite numbers of ``shape`` (None: any length >= 1
    there, the steps): integers or floats, not booleans (``a > 0`` was taken for 1 m/s^2). With
    ``humans_axis``, a human whose every entry is NaN is one not predicted (unseen: sensing.RangeLimited)."""
    try:
        array: np.ndarray | None = np.asarray(value)
    except (TypeError, ValueError):  # ragged rows
        array = None
    if (
        array is not None
        and array.dtype.kind in "iuf"
        and array.ndim == len(shape)
        and all(want is None or want == got for want, got in zip(shape, array.shape, strict=True))
    ):
        if any(want is None and got == 0 for want, got in zip(shape, array.shape, strict=True)):
            # no steps: recorded as positions of shape (0,), which review --check refused, --plot crashed on
            raise PipelineError(
                f"{_named(controller)}: act() must return {field} of at least one step (H >= 1) or None, got "
                f"shape {array.shape}"
            )
        finite = np.isfinite(array)
        if humans_axis is not None:
            others = tuple(a for a in range(array.ndim) if a != humans_axis)
            finite |= np.expand_dims(np.isnan(array).all(axis=others), others)
        if finite.all():
            return
        bad = array[~finite].flat[0]
        whole = " (NaN only for every entry of a human not predicted)" if humans_axis is not None else ""
        raise PipelineError(
            f"{_named(controller)}: act() must return {field} of finite numbers{whole}, got {bad}"
        )
    got = "ragged rows" if array is None else f"shape {array.shape}"
    if array is not None and array.dtype.kind not in "iuf":
        fits = array.ndim == len(shape) and all(
            w is None or w == g for w, g in zip(shape, array.shape, strict=True)
        )
        got = f"{array.dtype} values, not numbers" if fits else f"{got} of {array.dtype} values"
    raise PipelineError(f"{_named(controller)}: act() must return {field} {expected}, got {got}")


def checked_output(controller: Controller, out: object, obs: Observation) -> ControlOutput:
    """``out``, its arrays as float arrays, if it is a ``ControlOutput`` for ``obs``: ``accelerations``
    ``(M, 2)``, ``plan`` ``(M, H, 2)`` or None, ``prediction`` ``(H, N, 2)`` or None and each of
    ``iteration_predictions`` ``(H, N, 2)`` (finite integers or floats, no booleans; a prediction's human
    all NaN is one not predicted, e.g. out of a sensor's view), ``iterations`` an
    int >= 0, ``status`` a str, ``fallback`` a str or None (any name: the recording's schema takes a plugin's
    own), ``solve_time_s`` a finite number >= 0, ``potential`` a number or None, ``extra`` a dict of JSON
    values. Anything else (bare accelerations, a row short) is a one-line PipelineError naming the
    controller."""
    if not isinstance(out, ControlOutput):
        raise PipelineError(
            f"{_named(controller)}: act() must return a crowdsim.control.ControlOutput, got "
            f"{type(out).__module__}.{type(out).__qualname__}"
        )
    _check_arrays(controller, out, obs)
    _check_solver_fields(controller, out)
    # the loop and the recorder work on float arrays (a list of rows had no .tolist() for the recorder)
    return dataclasses.replace(
        out,
        accelerations=np.asarray(out.accelerations, dtype=float),
        plan=None if out.plan is None else np.asarray(out.plan, dtype=float),
        prediction=None if out.prediction is None else np.asarray(out.prediction, dtype=float),
        iteration_predictions=tuple(np.asarray(p, dtype=float) for p in out.iteration_predictions),
    )


def _check_arrays(controller: Controller, out: ControlOutput, obs: Observation) -> None:
    """``checked_output``'s arrays: their shapes for ``obs`` and their values."""
    m, n = obs.n_robots, obs.n_humans
    _check_array(
        controller, "accelerations", out.accelerations, (m, 2), f"of shape ({m}, 2), a row per robot"
    )
    if out.plan is not None:
        _check_array(controller, "plan", out.plan, (m, None, 2), f"of shape ({m}, H, 2) or None")
    if out.prediction is not None:
        _check_array(
            controller,
            "prediction",
            out.prediction,
            (None, n, 2),
            f"of shape (H, {n}, 2) or None",
            humans_axis=1,
        )
    if not isinstance(out.iteration_predictions, tuple | list):
        raise PipelineError(
            f"{_named(controller)}: act() must return iteration_predictions as a tuple of arrays, got "
            f"{type(out.iteration_predictions).__name__}"
        )
    for each in out.iteration_predictions:  # written by --record-iterations
        _check_array(
            controller, "iteration_predictions", each, (None, n, 2), f"of (H, {n}, 2) arrays", humans_axis=1
        )


def _check_solver_fields(controller: Controller, out: ControlOutput) -> None:
    """``checked_output``'s fields of the step's report: ``iterations``, ``status``, ``fallback``, ``extra``,
    ``solve_time_s`` and ``potential``."""
    if isinstance(out.iterations, bool) or not isinstance(out.iterations, int | np.integer):
        raise PipelineError(
            f"{_named(controller)}: act() must return iterations as an int, got {out.iterations!r}"
        )
    if not isinstance(out.status, str):
        raise PipelineError(f"{_named(controller)}: act() must return status as a str, got {out.status!r}")
    if out.fallback is not None and not isinstance(out.fallback, str):
        raise PipelineError(
            f"{_named(controller)}: act() must return fallback as a str or None, got {out.fallback!r}"
        )
    _check_extra(controller, out.extra)
    for name, value, may_be_none in (
        ("solve_time_s", out.solve_time_s, False),
        ("potential", out.potential, True),
    ):
        if not (value is None and may_be_none) and (isinstance(value, bool) or not isinstance(value, Real)):
            expected = "a number or None" if may_be_none else "a number"
            raise PipelineError(
                f"{_named(controller)}: act() must return {name} as {expected}, got {value!r}"
            )
    # the recording's schema: a wall time and a count are finite and never negative (a negative time also
    # became the summary's median)
    for name, value, expected in (
        ("solve_time_s", out.solve_time_s, "a finite number >= 0 (s)"),
        ("iterations", out.iterations, "an int >= 0"),
    ):
        try:
            fits = math.isfinite(value) and value >= 0
        except OverflowError:  # an int beyond a float's range (10**400): no step's time or count
            fits = False
        if not fits:
            raise PipelineError(
                f"{_named(controller)}: act() must return {name} as {expected}, got {value!r:.40}"
            )


def _check_extra(controller: Controller, extra: object) -> None:
    """PipelineError unless ``extra`` is a dict of JSON values, as the recordings write it (``/mpc/solver``'s
    ``extra`` is an object): a list was written against the schema, which ``review --check`` then refused,
    and a value JSON cannot hold ended the run in the recorder's error, which named no controller."""
    if not isinstance(extra, Mapping):
        raise PipelineError(
            f"{_named(controller)}: act() must return extra as a dict, got {type(extra).__name__}"
        )
    _check_json(controller, extra, "act() must return extra of")


def checked_description(controller: Controller) -> dict[str, Any]:
    """``controller.describe()`` as a dict of JSON values, its ``"config"`` (if any) a dict too, its
    ``"predictor_sha256"`` (if any) a str or None; otherwise a one-line PipelineError naming the
    controller."""
    described = called(controller, "describe")
    if not isinstance(described, Mapping):
        raise PipelineError(
            f"{_named(controller)}: describe() must return a dict, got {type(described).__name__}"
        )
    config = described.get("config", {})
    if not isinstance(config, Mapping):
        raise PipelineError(
            f"{_named(controller)}: describe()['config'] must be a dict, got {type(config).__name__}"
        )
    if "env" in config:  # episode_config puts it beside the simulator's settings, which it replaced
        raise PipelineError(
            f"{_named(controller)}: describe()['config'] must not set 'env': the simulator's settings are "
            "recorded there"
        )
    # what a controller states about itself; the episode's seed, scenario and sizes would relabel every
    # episode alike (their recordings, named by seed and scenario, overwrote one file), as a caller's meta
    clash = [key for key in OWN_FIELDS if key in described and key not in ("predictor_sha256", "config")]
    if clash:
        raise PipelineError(
            f"{_named(controller)}: describe() must not set {clash}: the episode sets them itself"
        )
    sha256 = described.get("predictor_sha256")
    if sha256 is not None and not isinstance(sha256, str):  # the records' and the recordings' schemas
        raise PipelineError(
            f"{_named(controller)}: describe()['predictor_sha256'] must be a str or None, got {sha256!r:.60}"
        )
    # as the recordings and the sweep's records write it: simulate stringified what JSON cannot hold into
    # the MCAP ("<object object at 0x...>") where a sweep refused the episode
    _check_json(controller, described, "describe() must return")
    return dict(described)


def _check_json(controller: Controller, value: object, what: str) -> None:
    """PipelineError ``"<controller>: <what> JSON values (...)"`` unless ``value`` is what the records and
    the recordings can write."""
    try:
        json.dumps(plain(value), allow_nan=False)
    except (TypeError, ValueError, RecursionError) as exc:
        raise PipelineError(
            f"{_named(controller)}: {what} JSON values (dicts, lists, strings, numbers, booleans, None), "
            f"got {exc}"
        ) from None


def checked_meta(meta: Mapping[str, Any] | None, where: str) -> dict[str, Any]:
    """``meta`` as a dict, unless it sets one of the episode's own fields (``OWN_FIELDS``): PipelineError
    naming ``where`` it was given. A string or a list (``meta="demo"``) failed in ``dict()``, naming
    nothing."""
    if meta is not None and not isinstance(meta, Mapping):
        raise PipelineError(f"{where}: meta must be a dict of fields to add, got {short_repr(meta)}")
    meta = dict(meta or {})
    clash = [key for key in OWN_FIELDS if key in meta]
    if clash:
        raise PipelineError(
            f"{where}: meta must not set {clash}: the episode sets {', '.join(OWN_FIELDS)} itself; "
            "give yours other names"
        )
    return meta


def episode_config(env_config: EnvConfig, described: Mapping[str, Any]) -> dict[str, Any]:
    """The effective config of an episode (the MCAP "config" metadata, a sweep record's "config"): the
    simulator's settings, then what a ``checked_description`` adds under "config" (the MPC's config,
    coupling, flocking, margins)."""
    return {"env": dataclasses.asdict(env_config), **described.get("config", {})}


def episode_meta(
    episode: Mapping[str, Any],
    env_config: EnvConfig,
    controller: str,
    predictor: str | None,
    described: Mapping[str, Any] | None,
    meta: Mapping[str, Any] | None,
    where: str,
    *,
    end_on_collision: bool = False,
) -> dict[str, Any]:
    """The meta ``on_reset`` gets: the episode (seed, scenario, sizes), who drives, the environment's
    config plus what the controller's ``describe()`` adds (``checked_description``), then ``meta``
    (``checked_meta``), which may not set any of those. ``end_on_collision``: whether a contact ends the
    episode (the gymnasium environment's; never in ``run_episode``), so that a review tells an episode a
    contact ended from one a loop of its own cut short on a step that touched."""
    extra = dict(described or {})
    full: dict[str, Any] = {
        **episode,
        "controller": controller,
        "predictor": predictor,
        "predictor_sha256": None,
        "config": episode_config(env_config, {"config": extra.pop("config", {})}),
        "end_on_collision": bool(end_on_collision),
    }
    full.update(extra)
    full.update(checked_meta(meta, where))
    return full
