"""The reset options of ``crowdmpc/CrowdNav-v0`` (crowdsim.gym_env, whose ``reset`` documents them): the
episode's scenario and sizes, or a hand-built ``Layout``, checked against the environment's spaces; and the
checks of the numbers its constructor and ``step`` take (``count``, ``numbers``).
"""

from __future__ import annotations

import warnings
from dataclasses import fields
from typing import TYPE_CHECKING, Any, Final

import numpy as np

from crowdsim.errors import LayoutWarning, SimulationError, texts_or_bools
from crowdsim.formations import check_robot_spacing, robot_layout
from crowdsim.scenarios import Layout, check_sizes, checked_layout

if TYPE_CHECKING:
    from crowdsim.env_config import EnvConfig

RESET_OPTIONS: Final[tuple[str, ...]] = ("scenario", "n_humans", "n_robots", "layout")
LAYOUT_SCENARIO: Final[str] = "layout"  # the scenario an episode from options["layout"] reports


def episode_options(
    options: dict[str, Any] | None,
    defaults: dict[str, Any],
    scene_limit: float,
    max_humans: int,
    max_robots: int,
) -> dict[str, Any]:
    """The episode's ``scenario``, ``n_humans`` and ``n_robots`` (and ``layout`` for a hand-built one):
    ``defaults`` (the constructor's) updated by ``options``; SimulationError for options the environment's
    spaces (``scene_limit`` m, ``max_humans``, ``max_robots``) cannot hold."""
    chosen = dict(defaults)
    if options is None:
        return chosen
    if not isinstance(options, dict):
        raise SimulationError(f"reset options must be a dict, got {type(options).__name__}")
    unknown = sorted(str(k) for k in options if k not in RESET_OPTIONS)
    if unknown:
        raise SimulationError(f"unknown reset options {unknown}; choose from {list(RESET_OPTIONS)}")
    if "layout" in options:
        layout = options["layout"]
        others = sorted(k for k in options if k != "layout")
        if others:
            raise SimulationError(f"reset option 'layout' sets the agents; drop {others}")
        if not isinstance(layout, Layout):
            raise SimulationError(f"options['layout'] must be a Layout, got {type(layout).__name__}")
        layout = checked_layout(layout)  # shapes and numbers first: the bounds are read off its arrays
        if not all(np.all(np.abs(getattr(layout, f.name)) <= scene_limit) for f in fields(Layout)):
            raise SimulationError(
                f"options['layout']: starts and goals must lie within ±{scene_limit:g} m "
                "(the observation's bounds assume so)"
            )
        sizes = {"n_humans": len(layout.human_starts), "n_robots": len(layout.robot_starts)}
        chosen = {"scenario": LAYOUT_SCENARIO, **sizes, "layout": layout}
    else:
        chosen.update(options)
        check_sizes(chosen["scenario"], chosen["n_humans"], chosen["n_robots"])
    if chosen["n_humans"] > max_humans:
        raise SimulationError(
            f"options: n_humans={chosen['n_humans']} exceeds this environment's max_humans="
            f"{max_humans}; make it with max_humans={chosen['n_humans']}"
        )
    if not 1 <= chosen["n_robots"] <= max_robots:
        source = "the layout's robots" if "layout" in chosen else "n_robots"
        more = f"; make it with max_robots={chosen['n_robots']}" if chosen["n_robots"] > max_robots else ""
        raise SimulationError(
            f"options: {source} must be in [1, max_robots={max_robots}], got {chosen['n_robots']}{more}"
        )
    chosen["n_humans"], chosen["n_robots"] = int(chosen["n_humans"]), int(chosen["n_robots"])
    return chosen


def warn_formation(config: EnvConfig, n_robots: int) -> None:
    """A LayoutWarning from the constructor where ``config``'s formation of its ``n_robots`` puts neighbours
    in contact at its radius: every reset without ``options["layout"]`` is then refused, and said so only
    at the first. A warning, not a refusal: a user of hand-built layouts alone may want that radius."""
    starts, _ = robot_layout(n_robots, config.formation, spacing=config.robot_spacing)
    try:
        check_robot_spacing(starts, config.radius, config.formation, n_robots)
    except SimulationError as exc:
        warnings.warn(f"{exc}: a reset without options['layout'] is refused", LayoutWarning, stacklevel=3)


def numbers(action: object, what: str) -> np.ndarray:
    """``action`` as a float array; SimulationError naming ``what`` when it holds no numbers (numpy's own
    "could not convert string to float" named nothing), or texts or booleans, which ``astype(float)`` read
    as numbers ("0.5" as 0.5, True as 1.0) where ``CrowdEnv.step`` refuses them."""
    try:
        raw = np.asarray(action)
        values = None if np.iscomplexobj(raw) else raw.astype(float)  # numpy drops an imaginary part
    except (TypeError, ValueError) as exc:
        raise SimulationError(
            f"{what} must be an array of numbers, got {type(action).__name__} ({exc})"
        ) from None
    if values is None:
        raise SimulationError(f"{what} must be an array of real numbers, got complex ones")
    held = texts_or_bools(raw)
    if held is not None:
        raise SimulationError(f"{what} must be an array of real numbers, got one of {held}")
    return values


def count(value: object, name: str, low: int, high: int) -> int:
    """``value`` as an int in ``[low, high]``; SimulationError naming ``name`` otherwise."""
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or not low <= value <= high:
        raise SimulationError(f"{name} must be an int in [{low}, {high}], got {value!r}")
    return int(value)
