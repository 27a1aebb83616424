"""``crowdmpc simulate``'s refusal of choices its controller would ignore: a value accepted must change the
run, so the ones that could not are one-line errors before any episode."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from pipelines.errors import PipelineError
from pipelines.loop.spec import CONTROLLER_KINDS, is_shipped

if TYPE_CHECKING:
    from collections.abc import Iterable

    from pipelines.config import RunConfig
    from pipelines.experiments.tasks import Cell
    from pipelines.loop.controllers import ControllerSpec

# The shipped MPCs: the controllers that read flocking, record_iterations and [mpc].
MPC_CONTROLLERS = tuple(name for name, kind in CONTROLLER_KINDS.items() if kind.uses_predictor)


def _shown(config: RunConfig, section: str, key: str, value: Any) -> str:
    """A chosen value as an error names it: "--no-flocking", "--set mpc.horizon 10", "run.toml: mpc.horizon
    10" (a switch given as an option says its value by its name)."""
    label = config.label(section, key)
    source = config.source(section, key)
    if isinstance(value, bool):
        return label if source is not None and source.kind == "cli" else f"{label} {str(value).lower()}"
    return f"{label} {value}"


def _refuse(shown: list[str], controller: str, plans_with: str, keys: str) -> None:
    if shown:
        listed = shown[0] if len(shown) == 1 else f"{', '.join(shown[:-1])} and {shown[-1]}"
        raise PipelineError(
            f"{listed}: controller {controller!r} plans with no {plans_with}; {keys} apply to "
            f"the controllers that do ({', '.join(MPC_CONTROLLERS)})"
        )


def check_choices_apply(config: RunConfig, spec: ControllerSpec) -> None:
    """Refuse what ``spec``'s controller would ignore: a predictor, margins or coupling for one that plans
    with no predictor, and flocking, record_iterations or an [mpc] value for ORCA and the straight line,
    which plan with no MPC. Only values the user chose count (``RunConfig.chosen``: a config file shared
    with cmpc may state the defaults); a plugin reads the spec as it sees fit, so only its predictor facts
    are checked. Then ``record_iterations`` behind a sensor or without ``record``: nothing would write it."""
    if spec.predictor_name is None:  # ORCA, the straight line, a plugin that predicts nothing
        chosen = config.controller
        _refuse(
            [
                _shown(config, "controller", key, value)
                for key, value, given in (
                    ("predictor", chosen.predictor, config.chosen("controller", "predictor")),
                    ("margins", chosen.margins, spec.margins.mode != "none"),
                    ("coupling", spec.coupling, spec.coupling != "ibr"),
                )
                if given
            ],
            spec.controller,
            "predictor",
            "predictor, margins and coupling",
        )
    if is_shipped(spec.controller) and spec.controller not in MPC_CONTROLLERS:
        mpc = [("controller", key) for key in ("flocking", "record_iterations")]
        mpc += [("mpc", key) for key in config.values["mpc"]]
        _refuse(
            [
                _shown(config, section, key, config.values[section][key])
                for section, key in mpc
                if config.chosen(section, key)
            ],
            spec.controller,
            "MPC",
            "flocking, record_iterations and [mpc]",
        )
    if not config.simulate.sensor_tracks and config.simulate.sensor_range is None:
        raise PipelineError(
            f"{_shown(config, 'simulate', 'sensor_tracks', False)}: track lengths are a sensor's; give "
            "--sensor-range M too (or [simulate] sensor_range)"
        )
    if spec.record_iterations and config.simulate.sensor_range is not None:
        # RangeLimited drops the predictions: they are of the humans in view, the recording's of every human
        raise PipelineError(
            f"{config.label('controller', 'record_iterations')}: a controller behind "
            f"{config.label('simulate', 'sensor_range')} records no predictions (they are of the humans in "
            "view only); record without the iterations, or without the sensor"
        )
    if spec.record_iterations and config.simulate.record is None:
        raise PipelineError(
            f"{config.label('controller', 'record_iterations')}: the iterations are written to the MCAP "
            "recordings; give --record DIR too (or [simulate] record)"
        )


def goal_room_note(
    spec: ControllerSpec, n_robots: int, formation: str, *, formation_settable: bool
) -> str | None:
    """A line for an MPC whose d_min is not below the distance between two robots' goals, None otherwise:
    the MPC keeps every pair of robots d_min apart (Eq. 12), which may keep them from standing on their goals
    at once, and the episodes then time out for a reason no metric names. Measured (constant velocity, no
    humans, 2 episodes each): 3 robots in the row, goals 1.0 m apart, CMPC succeeded in none at d_min 1.0,
    1.1 and 1.2 (in both at 0.98), DMPC in both at 1.0 and in none at 1.1 and 1.2; in the wedge, goals
    1.2 m apart, both controllers succeeded in both at 1.2 and 1.3 (a robot may stop 0.3 m off its goal)."""
    import numpy as np

    from crowdsim.scenarios import choose_formation, robot_layout
    from pipelines.loop.mpc_setup import mpc_config

    if spec.controller not in MPC_CONTROLLERS or not is_shipped(spec.controller) or n_robots < 2:
        return None
    shape = choose_formation(n_robots) if formation == "auto" else formation
    goals = robot_layout(n_robots, shape)[1]  # type: ignore[arg-type]  # EnvConfig checked the name
    gaps = np.linalg.norm(goals[:, None] - goals[None], axis=-1)[np.triu_indices(n_robots, k=1)]
    d_min, gap = mpc_config(spec).d_min, float(gaps.min())
    if d_min < gap - 1e-9:
        return None
    hint = "; [env] formation wedge spaces them 1.2 m apart" if formation_settable and shape == "row" else ""
    return (
        f"note: the MPC's d_min {d_min:g} m is not below the {gap:g} m between two robots' goals ({shape} of "
        f"{n_robots}), and it keeps them d_min apart: they may never stand on their goals at once (3 robots "
        f"in the row, no humans: CMPC reached them in no episode at d_min 1.0, DMPC in none at 1.1){hint}"
    )


def goal_room_notes(cells: Iterable[Cell]) -> list[str]:
    """A sweep's ``goal_room_note`` lines, once per method, each naming it."""
    notes: dict[str, str] = {}
    for cell in cells:
        formation = cell.world.env_config().formation
        note = goal_room_note(cell.spec, cell.n_robots, formation, formation_settable=False)
        if note is not None and cell.method not in notes:
            notes[cell.method] = note.replace("note: ", f"note: method {cell.method!r}: ", 1)
    return list(notes.values())
