"""The notes on calibrated margins planned with where they were not measured (simulate's and sweep's, each a
"note: ..." line or None): under other conventions or among a replayed crowd (``calibration_world_note``),
in another world or crowd motion (``calibration_physics_note``), with another controller
(``calibration_controller_note``), team or crowd size (``calibration_team_note``) or another view of the
humans (``sensor_margins_note``). Not refusals: an experiment may hold the margins fixed across any of
these."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, Final

from pipelines.loop.spec import MPC_CONTROLLERS

if TYPE_CHECKING:
    from types import EllipsisType

    from pipelines.config import RunConfig
    from pipelines.loop.controllers import ControllerSpec
    from pipelines.loop.margins_read import Planned as Lookup
    from predictors.calibration import Calibration
    from predictors.manifest import ZooEntry

    Planned = Calibration | None | EllipsisType  # the block planned with, None: none; ...: not read yet
    # the zoo entry the predictor loads, whose model kind a quoted calibrate command registers (--plugin)
    Entry = ZooEntry | None | EllipsisType  # None: a registered predictor or none; ...: located for it


def calibration_notes(
    spec: ControllerSpec,
    config: RunConfig,
    located: Lookup | EllipsisType = ...,
    entry: Entry = ...,
) -> list[str]:
    """Every note above for a simulate run of ``spec`` under ``config``, of the block its controller plans
    with as the run read it (``located``: ``margins_read.look_up``'s, of a refusal the block it refused;
    ``...``: each note looks it up) and of its predictor's zoo ``entry`` as the run located it (``...``: a
    note quoting a command locates it)."""
    from pipelines.loop.margins_read import block_of

    block = block_of(located)
    env, sim = config.env, config.simulate
    view = sim.sensor_range, sim.sensor_tracks
    visibility = "visible" if env.robots_visible else "invisible"
    found = (
        calibration_world_note(spec, env.profile, visibility, env.crowd, *view, as_read=block, entry=entry),
        sensor_margins_note(spec, *view, as_read=block, entry=entry),
        calibration_controller_note(spec, *view, as_read=block, entry=entry),
        calibration_team_note(spec, [config.scenario.humans], config.scenario.robots, *view, as_read=block),
        calibration_physics_note(spec, changed_physics(config), *view, as_read=block),
    )
    return [note for note in found if note is not None]


def calibration_world_note(
    spec: ControllerSpec,
    profile: str,
    visibility: str,
    crowd: str = "orca",
    sensor_range: float | None = None,
    sensor_tracks: bool = True,
    as_read: Planned = ...,
    entry: Entry = ...,
) -> str | None:
    """A line for closed-loop conformal margins calibrated under other conventions than the run's (the
    profile, the robots' visibility) or among other humans (a replayed ``crowd``: calibrate runs ORCA's),
    None otherwise: one block is stored per predictor, alpha and sensor range (the block planned with
    behind ``sensor_range`` m is read), the humans' motion its margins cover is that of the conventions it
    ran under, and a run under others planned with it silently. Not refused: an experiment may hold the
    margins fixed across conventions (conventions, docs/safe_crossing.md)."""
    from predictors.calibration import remaking_view
    from predictors.calibration_store import recalibrate_command
    from predictors.conformal import alpha_text

    margins, name = spec.margins, spec.predictor_name
    planned = spec.behind(sensor_range, sensor_tracks)
    block = _planned_block(planned, as_read) if margins.source == "closed-loop" else None
    if block is None or name is None:
        return None
    if crowd != "orca":  # whatever the conventions: calibrate's episodes are ORCA's crowds
        return (
            f"note: the closed-loop margins of {name!r} at alpha={alpha_text(margins.alpha)} were calibrated "
            f"among ORCA's humans, this run replays BIWI's {crowd}: there they cover less than calibrated at "
            "the first horizon steps (docs/replayed_crowds.md; conformal:ALPHA:real, calibrated on real "
            "people, covers more)"
        )
    measured = (block.details.get("profile"), block.details.get("visibility"))
    if None in measured or measured == (profile, visibility):
        return None
    view, why = remaking_view(block, (sensor_range, sensor_tracks))
    command = recalibrate_command(name, margins.source, margins.alpha, kind=_kind(entry))
    command += _block_options(block, view)
    return (
        f"note: the closed-loop margins of {name!r} at alpha={alpha_text(margins.alpha)} were calibrated "
        f"under profile {measured[0]} with robots {measured[1]}, this run is {profile} with robots "
        f"{visibility}: their coverage here is not measured ({command} --profile {profile} --visibility "
        f"{visibility} measures it{why or _REPLACING}; CROWDMPC_ZOO=DIR keeps it apart)"
    )


# The simulator settings of the humans' motion and of the geometry (``World.env_settings`` names) that a
# closed-loop calibration ran at their defaults: `calibrate` reads no config file nor --set.
CROWD_SETTINGS: Final[tuple[str, ...]] = (
    "crossing",
    "orca.max_neighbors",
    "orca.neighbor_dist",
    "orca.time_horizon",
    "orca_radius_margin",
    "spawn_separation",
)


def calibration_physics_note(
    spec: ControllerSpec,
    changed: list[str],
    sensor_range: float | None = None,
    sensor_tracks: bool = True,
    as_read: Planned = ...,
) -> str | None:
    """A line for closed-loop margins planned with in another world than the one `calibrate` runs (Table I's
    [world], the profile's crowd): ``changed`` names the settings that differ ("world.v_pref 0.5",
    "env.orca.time_horizon 2"); faster people or larger robots move otherwise than the margins measured.
    None without such margins or changes. Not refused: an experiment may hold the margins fixed."""
    from predictors.conformal import alpha_text

    margins, name = spec.margins, spec.predictor_name
    planned = spec.behind(sensor_range, sensor_tracks)
    block = _planned_block(planned, as_read) if margins.source == "closed-loop" else None
    if block is None or name is None or not changed:
        return None
    return (
        f"note: the closed-loop margins of {name!r} at alpha={alpha_text(margins.alpha)} were calibrated in "
        "Table I's world among the profile's ORCA humans (calibrate takes no [world] or [env] settings); "
        f"this run sets {', '.join(changed)}: their coverage here is not measured"
    )


def changed_physics(config: RunConfig) -> list[str]:
    """The [world] values and the [env] / [env.orca] values of ``CROWD_SETTINGS`` the run sets to other than
    their defaults (the calibration's)."""
    chosen = [("world", key) for key in config.values["world"]]
    chosen += [("env", key) for key in config.values["env"] if key in CROWD_SETTINGS]
    chosen += [("env.orca", key) for key in config.values["env.orca"] if f"orca.{key}" in CROWD_SETTINGS]
    return [
        f"{s}.{k} {config.values[s][k]}" for s, k in chosen if config.values[s][k] != config.default(s, k)
    ]


def calibration_team_note(
    spec: ControllerSpec,
    humans: Sequence[int],
    n_robots: int,
    sensor_range: float | None = None,
    sensor_tracks: bool = True,
    as_read: Planned = ...,
) -> str | None:
    """A line for closed-loop margins planned with by another team than calibrate's (its episodes run
    ``PAPER_ROBOTS`` robots) or among crowds of ``humans`` outside the block's sizes, None otherwise: more
    robots or people move otherwise near each other than the margins measured, and the run planned with
    them without a word."""
    from crowdsim.world import PAPER_ROBOTS
    from predictors.conformal import alpha_text
    from predictors.text_table import counted

    block = _planned_block(spec.behind(sensor_range, sensor_tracks), as_read)
    made = block.details.get("humans") if block is not None else None
    if block is None or block.source != "closed-loop" or not isinstance(made, list) or not made:
        return None
    outside = sorted({n for n in humans if not min(made) <= n <= max(made)})
    # several crowd sizes are "4, 15 humans"; one is counted as such ("1 human")
    sizes = counted(outside[0], "human") if len(outside) == 1 else f"{', '.join(map(str, outside))} humans"
    differ = ([counted(n_robots, "robot")] if n_robots != PAPER_ROBOTS else []) + ([sizes] if outside else [])
    if not differ:
        return None
    return (
        f"note: the closed-loop margins of {spec.predictor_name!r} at alpha={alpha_text(spec.margins.alpha)} "
        f"were calibrated with {PAPER_ROBOTS} robots among {min(made)}-{max(made)} humans (calibrate's "
        f"episodes; --humans sets their crowds), this run has {' and '.join(differ)}: their coverage here "
        "is not measured"
    )


def calibration_controller_note(
    spec: ControllerSpec,
    sensor_range: float | None = None,
    sensor_tracks: bool = True,
    as_read: Planned = ...,
    entry: Entry = ...,
) -> str | None:
    """A line for closed-loop margins calibrated with another controller than the run's (``calibrate
    --controller dmpc`` for a CMPC run), None otherwise (``controller_note``)."""
    block = _planned_block(spec.behind(sensor_range, sensor_tracks), as_read)
    view = (sensor_range, sensor_tracks)
    return None if block is None else controller_note(block, spec.controller, entry, view)


def controller_note(
    block: Calibration, controller: str, entry: Entry = ..., view: tuple[float | None, bool] = (None, True)
) -> str | None:
    """A line for a run of MPC ``controller`` planning with the margins of ``block``, a closed-loop block
    calibrated with another controller (``calibrate --controller``, recorded in its details), None otherwise,
    as ``calibration_world_note`` says it of another profile: CMPC's and DMPC's robots move
    otherwise, and so do the humans who answer them, but one block is stored per alpha (a recalibration
    replaces it) and a run planned with the other controller's silently. Not refused: an experiment may hold
    the margins fixed across controllers. ``entry``: the predictor's zoo entry as the run located it, whose
    model kind the quoted command registers (``...``: the command locates it). ``view``: the run's sensor
    range and track lengths, the command's where calibrate refuses the block's (``remaking_view``)."""
    from predictors.calibration import remaking_view
    from predictors.calibration_store import calibrate_command
    from predictors.conformal import alpha_text

    made = block.details.get("controller") if block.source == "closed-loop" else None
    if made is None or made == controller:
        return None
    view, why = remaking_view(block, view)
    command = calibrate_command(block, kind=_kind(entry), view=view, controller=controller)
    return (
        f"note: the closed-loop margins of {block.predictor!r} at alpha={alpha_text(block.alpha)} were "
        f"calibrated with controller {made}, this run's is {controller}: their coverage here is not measured "
        f"({command} measures it{why or _REPLACING}; CROWDMPC_ZOO=DIR keeps it apart)"
    )


# where the quoted command makes the block planned with again (else ``beyond_remaking`` says what it makes)
_REPLACING: Final[str] = ", replacing that block for every run"


# What docs/replayed_crowds.md measured behind a 3 m sensor, by calibration source (social_lstm_eth and
# constant velocity, alpha 0.1; benchmarks/replay_coverage.py --sensor-range 3)
_MEASURED_BEHIND = {
    "closed-loop": "alpha=0.1 covered 0.83-0.87 among ORCA's humans, where 0.90 was calibrated",
    "real": "alpha=0.1 covered 0.85-0.92 among BIWI's people, 0.93-0.99 with every person in view",
}


def sensor_margins_note(
    spec: ControllerSpec,
    sensor_range: float | None,
    sensor_tracks: bool = True,
    as_read: Planned = ...,
    entry: Entry = ...,
) -> str | None:
    """A line for calibrated margins made with another view of the humans than the run's (``sensor_range`` m;
    None: every human seen), None otherwise. A calibration records the sensor its robots were behind
    (``calibrate --sensor-range``; none for a real one or one made before the option), and a run plans with
    the block made behind its own sensor where one is stored (``find_calibration``), else with another: made
    with every person in view, its margins cover less behind a sensor, where a person just come into view is
    predicted from a track of one or two positions (measured at 3 m: docs/replayed_crowds.md); made behind
    a sensor, they are wider than a robot that sees everyone needs, and behind another range their coverage
    is not measured, nor behind a tracker that reports track lengths where the calibration's did not, or
    the other way (``sensor_tracks``). Not refused: the safe configuration
    kept its collision rate behind a 3 m sensor among ORCA's humans (docs/extending.md)."""
    from predictors.calibration_store import recalibrate_command
    from predictors.conformal import alpha_text

    planned = spec.behind(sensor_range, sensor_tracks)
    margins, name = planned.margins, spec.predictor_name
    block = _planned_block(planned, as_read)
    if block is None or name is None:
        return None
    made = block.sensor_range
    if (made, block.sensor_tracks) == (sensor_range, sensor_tracks) or (made, sensor_range) == (None, None):
        return None
    alpha = alpha_text(margins.alpha)
    command = ""
    if margins.source == "closed-loop":  # a real calibration has no sensor: recorded people, all in view
        own = "with every person in view" if sensor_range is None else "behind this run's sensor"
        options = _block_options(block, (sensor_range, sensor_tracks))
        recalibrate = recalibrate_command(name, margins.source, margins.alpha, kind=_kind(entry))
        command = f"; {recalibrate}{options} calibrates {own}, stored beside that block"
    if sensor_range is None:
        return (
            f"note: the closed-loop margins of {name!r} at alpha={alpha} were calibrated behind a sensor of "
            f"{made:g} m, this run's robots see every human: made for people just come into view, they are "
            f'wider than it needs (docs/replayed_crowds.md, "Behind a sensor"){command}'
        )
    if made == sensor_range:  # the same range, the track lengths the other way
        given = ("without", "with") if sensor_tracks else ("with", "without")
        return (
            f"note: the closed-loop margins of {name!r} at alpha={alpha} were calibrated behind a sensor of "
            f"{made:g} m {given[0]} the tracker's track lengths, this run's controller plans {given[1]} "
            f"them: it classes the people who just came into view otherwise, and the coverage here is not "
            f"measured{command}"
        )
    if made is not None:  # behind another range: more or fewer people come into view, by how much unmeasured
        return (
            f"note: the closed-loop margins of {name!r} at alpha={alpha} were calibrated behind a sensor of "
            f"{made:g} m, this run's is {sensor_range:g} m: their coverage here is not measured{command}"
        )
    return (
        f"note: the {margins.source} margins of {name!r} at alpha={alpha} were calibrated with every person "
        f"in view; behind a sensor of {sensor_range:g} m a person just come into view is predicted from a "
        'short track, and they cover less than calibrated (docs/replayed_crowds.md, "Behind a sensor": at '
        f"3 m, {_MEASURED_BEHIND[margins.source]}){command}"
    )


def _planned_block(spec: ControllerSpec, as_read: Planned = ...) -> Any:
    """The stored calibration block an MPC's calibrated margins plan with (behind ``margins.sensor_range``:
    ``ControllerSpec.behind``), None for other margins or
    controllers, or where there is none (or it is of other weights: refused with its own line where the
    margins resolve); the notes above read its details. ``as_read``: that block as the run read it (``...``:
    looked up here)."""
    from pipelines.loop.margins import CALIBRATED_MODES
    from predictors.calibration_store import find_calibration
    from predictors.errors import PredictorError
    from predictors.registry import checkpoint_sha256

    margins, name = spec.margins, spec.predictor_name
    if spec.controller not in MPC_CONTROLLERS or margins.mode not in CALIBRATED_MODES or name is None:
        return None
    if as_read is not ...:
        return as_read
    try:
        return find_calibration(
            name,
            margins.source,
            margins.alpha,
            sha256=checkpoint_sha256(name),
            sensor_range=margins.sensor_range,
            sensor_tracks=margins.sensor_tracks,
        )
    except PredictorError:
        return None


def _kind(entry: Entry) -> str | None | EllipsisType:
    """The model kind of ``entry`` that a quoted calibrate command registers, ``...`` where the caller
    located none (the command then reads the manifest for it)."""
    return ... if entry is ... else None if entry is None else entry.model


def _block_options(block: Any, view: tuple[float | None, bool]) -> str:
    """``calibrate``'s options that made ``block`` but for its conventions and sensor: the command the note
    gives makes the same calibration (its horizon, episodes, crowds, controller, seed, scoring range) under
    the run's, not the defaults' (200 episodes, horizon 4, CMPC), behind the sensor of ``view`` (range, None:
    every human in view; track lengths given)."""
    details = block.details
    near = details.get("near", 3.0)
    options = [f"--horizon {len(block.quantiles)}"]
    for option, key in (("--episodes", "episodes"), ("--seed", "seed"), ("--controller", "controller")):
        if key in details:
            options.append(f"{option} {details[key]}")
    if isinstance(details.get("humans"), list):
        options.append("--humans " + ",".join(str(h) for h in details["humans"]))
    options.append(f"--near {'inf' if near is None else f'{near:g}'}")  # null: everyone scored
    if view[0] is not None:  # its robots behind a sensor
        options.append(f"--sensor-range {view[0]:g}" + ("" if view[1] else " --no-sensor-tracks"))
    return " " + " ".join(options)
