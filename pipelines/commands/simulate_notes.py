"""What ``crowdmpc simulate`` says before its episodes: the notes on its team, horizon, sizes, tolerance,
zoo model and calibration, of the entry and block its controller then plans with (read once for both,
pipelines.commands.simulate_reads)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from pipelines.errors import print_note

if TYPE_CHECKING:
    from pipelines.commands.simulate_reads import PredictorRead
    from pipelines.config import RunConfig
    from pipelines.loop.controllers import ControllerReads, ControllerSpec


def noted_reads(cfg: RunConfig, spec: ControllerSpec, checked: PredictorRead | None) -> ControllerReads:
    """simulate's notes printed, and what its controller plans with: the zoo entry and calibration block
    they describe, read once for both (``checked``: the predictor as its checks read it, None: none yet)."""
    from pipelines.commands import simulate_checks as checks
    from pipelines.commands import team_notes
    from pipelines.commands.calibration_notes import calibration_notes
    from pipelines.commands.quick_check_notes import quick_check_note
    from pipelines.commands.simulate_reads import read_once
    from pipelines.loop.margins_read import Refused

    scenario, formation, spacing = cfg.scenario, cfg.env.formation, cfg.env.robot_spacing
    entry, read = read_once(checked, spec, cfg)  # for the notes and the controller
    notes = (
        team_notes.separate_goals_note(spec, scenario.robots, formation, spacing),
        team_notes.flock_note(spec, scenario.robots, formation, spacing),
        team_notes.goal_room_note(spec, scenario.robots, formation, spacing),
        team_notes.radius_note(spec, scenario.robots, cfg.env.radius, formation, spacing),
        checks.horizon_note(spec, entry),
        checks.size_note(spec, scenario.humans, scenario.robots),
        checks.tolerance_note(spec),
        *checks.zoo_notes(spec.predictor_name, entry),
        # not before the controller's refusal of a model that does not load (a plugin not registered)
        None if isinstance(read.predictor, Refused) else quick_check_note(spec.predictor_name, entry),
        *calibration_notes(spec, cfg, read.calibration, entry),
    )
    for note in filter(None, notes):
        print_note(note)
    return read
