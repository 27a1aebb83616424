"""The choices that change nothing but a run's record, and the words that refuse them, shared by ``simulate``
(pipelines.commands.simulate_checks, for its one controller, crowd and team) and ``sweep``
(``check_sweep_choices``, where no cell of the plan would read them): track lengths for a controller that
reads no pasts, the robots' visibility for a crowd that sees no robot, ORCA's sampling rules for a replayed
crowd, a team's settings for a lone robot. A sweep made a cell of its own per such value, whose episodes
were the default's."""

from __future__ import annotations

from collections.abc import Collection
from typing import TYPE_CHECKING, Any, Final

from pipelines.errors import PipelineError
from pipelines.loop.spec import MPC_CONTROLLERS, is_shipped
from pipelines.loop.unread import FLOCKING_KEYS

if TYPE_CHECKING:
    from pipelines.commands.sweep_vary import Varied
    from pipelines.config import RunConfig
    from pipelines.experiments.cells import Experiment
    from pipelines.experiments.tasks import Cell

# ORCA's rules for sampling its humans (crowdsim.crossings), which place no person of a replay.
SAMPLING_KEYS: Final[tuple[str, str]] = ("crossing", "spawn_separation")
# What a team has and a lone robot has not: Eq. 15's pairs and what tunes them (mpc.stall drops a stalled
# robot's pairs), DMPC's joint re-plans of two robots and its order among several, and the team's layout.
TEAM_MPC_KEYS: Final[tuple[tuple[str, str], ...]] = (
    ("controller", "flocking"),
    *(("mpc", key) for key in sorted(FLOCKING_KEYS)),
    *(("mpc", key) for key in ("stall_release_s", "dmpc_pairs", "dmpc_conflicts", "dmpc_order")),
)
TEAM_ENV_KEYS: Final[tuple[tuple[str, str], ...]] = (("env", "goal_assignment"), ("env", "robot_spacing"))
LONE_FORMATION: Final[str] = "antipodal"  # a lone robot's: it crosses to the opposite side, as each does


def shown_choice(config: RunConfig, section: str, key: str, value: Any) -> str:
    """A chosen value as an error names it: "--no-flocking", "--set mpc.horizon 10", "run.toml: mpc.horizon
    10" (a switch given as an option says its value by its name)."""
    label = config.label(section, key)
    source = config.source(section, key)
    if isinstance(value, bool):
        return label if source is not None and source.kind == "cli" else f"{label} {str(value).lower()}"
    text = str(value)  # a 900 kB string in a file is no 900 kB error line
    return f"{label} {text if len(text) <= 80 else text[:77] + '...'}"


def typed(config: RunConfig, section: str, key: str) -> bool:
    """Whether an option or ``--set`` gave the value: a file's may serve other runs (every team size, every
    crowd), and a sweep folder's recorded config reads back as a file's."""
    source = config.source(section, key)
    return source is not None and source.kind != "file"


def untracked_because(controllers: Collection[str]) -> str | None:
    """Why track lengths change nothing for every one of ``controllers``, None where one may read them:
    ORCA and the straight line act on the humans' current positions and velocities, never on their pasts, so
    a tracker that reports no track lengths drives them as one that does (a plugin reads what it likes)."""
    names = list(dict.fromkeys(controllers))
    if not names or any(not is_shipped(name) or name in MPC_CONTROLLERS for name in names):
        return None
    who = (
        f"controller {names[0]!r} acts"
        if len(names) == 1
        else f"controllers {', '.join(map(repr, names[:-1]))} and {names[-1]!r} act"
    )
    return (
        f"{who} on the humans' current positions and velocities, not their pasts, so track lengths change "
        f"nothing for {'it' if len(names) == 1 else 'them'}"
    )


def unseen_because(crowd: str) -> str | None:
    """Why the robots' visibility changes nothing among ``crowd``, None where it may: a plain replay walks
    its recorded tracks, seeing no robot whether the robots are visible or not."""
    from crowdsim.reaction import reacts

    if crowd == "orca" or reacts(crowd):
        return None
    return (
        f"crowd {crowd!r} replays people who see no robot whatever the visibility (crowd {crowd}_reactive "
        "yields to visible robots)"
    )


def visibility_shown(config: RunConfig) -> str:
    """The robots' visibility as the command line chose it: "--visibility invisible", "--set
    env.robots_visible false"."""
    visibility = "visible" if config.env.robots_visible else "invisible"
    source = config.source("env", "robots_visible")
    shown = config.label("env", "robots_visible")
    if source is not None and source.kind == "cli":
        return f"{shown} {visibility}"
    return f"{shown} {str(visibility == 'visible').lower()}"


def unsampled_because(crowd: str) -> str | None:
    """Why ``SAMPLING_KEYS`` change nothing among ``crowd``, None where they may: a replay's people stand
    where their tracks put them."""
    if crowd == "orca":
        return None
    return (
        f"crowd {crowd!r} replays recorded people, placed by their tracks; crossing and spawn_separation "
        "sample the humans of crowd orca"
    )


def team_keys(config: RunConfig, mpc: bool) -> list[tuple[str, str]]:
    """The settings a lone robot does not read that ``config`` may give: the team's layout, its formation
    but antipodal, and for a shipped MPC (``mpc``) ``TEAM_MPC_KEYS``."""
    team = [*TEAM_ENV_KEYS, *(TEAM_MPC_KEYS if mpc else ())]
    return team + ([("env", "formation")] if config.env.formation != LONE_FORMATION else [])


def teamless_refusal(config: RunConfig, shown: str) -> PipelineError:
    """The refusal of the team's setting ``shown`` for the lone robot of ``config``."""
    return PipelineError(
        f"{shown} changes nothing here, where {config.label('scenario', 'robots')} 1 leaves the robot no "
        "teammate to flock, re-plan or stand in formation with; leave it out"
    )


def check_sweep_choices(config: RunConfig, experiment: Experiment) -> None:
    """Refuse what an option, ``--set`` or ``--vary`` chose for a sweep that no cell of ``experiment`` (the
    sweep's, configured) would read, in simulate's words: --no-sensor-tracks where every method is ORCA or
    the straight line, a visibility, crossing or spawn_separation among a plain replayed crowd, a team's
    setting where every cell has one robot. Only a run is checked: a report (``--report-only``), a resume's
    records and ``--reuse``'s read what the folders recorded, as they ran."""
    from pipelines.commands.sweep_vary import varied

    cells = experiment.cells(None, config.scenario.robots)
    varies = {(v.section, v.key): v for v in varied(config)} if typed(config, "sweep", "vary") else {}
    if typed(config, "simulate", "sensor_tracks") and not config.simulate.sensor_tracks:
        why = untracked_because([cell.spec.controller for cell in cells])
        if why is not None:
            raise PipelineError(
                f"{shown_choice(config, 'simulate', 'sensor_tracks', False)}: {why}; leave it out"
            )
    unseen = [unseen_because(cell.world.crowd) for cell in cells]
    if typed(config, "env", "robots_visible") and None not in unseen:
        raise PipelineError(f"{visibility_shown(config)}: {unseen[0]}; leave it out")
    unsampled = [unsampled_because(cell.world.crowd) for cell in cells]
    for key in SAMPLING_KEYS:
        shown = _chosen(config, varies, "env", key)
        if shown is not None and None not in unsampled:
            raise PipelineError(f"{shown}: {unsampled[0]}; leave it out")
    _check_team(config, varies, cells)


def _check_team(config: RunConfig, varies: dict[tuple[str, str], Varied], cells: tuple[Cell, ...]) -> None:
    """``team_keys`` chosen where every cell has one robot (``--robots 1``, no --vary scenario.robots
    beyond it); a team's [mpc] and [controller] settings where every cell that plans with a shipped MPC
    does (ORCA and the straight line read none; a plugin reads what it likes)."""
    teams = [cell for cell in cells if cell.n_robots != 1]
    planning = [cell for cell in cells if cell.spec.kind.uses_predictor]
    reading = [cell for cell in planning if cell in teams or not _shipped_mpc(cell.spec.controller)]
    keys = team_keys(config, mpc=bool(planning))
    if ("env", "formation") in varies and ("env", "formation") not in keys:  # a column per formation
        keys.append(("env", "formation"))
    for section, key in keys:
        shown = _chosen(config, varies, section, key)
        if shown is not None and not (teams if section == "env" else reading):
            raise teamless_refusal(config, shown)


def _shipped_mpc(controller: str) -> bool:
    return is_shipped(controller) and controller in MPC_CONTROLLERS


def _chosen(config: RunConfig, varies: dict[tuple[str, str], Varied], section: str, key: str) -> str | None:
    """How the command line chose ``section.key`` for a sweep: ``--vary`` naming its values, or the option
    or ``--set`` item with its value; None where it chose none."""
    from pipelines.commands.sweep_vary import shown

    vary = varies.get((section, key))
    if vary is not None:
        return f"{config.label('sweep', 'vary')} {section}.{key}={','.join(shown(v) for v in vary.values)}"
    if typed(config, section, key):
        return shown_choice(config, section, key, config.values[section][key])
    return None
