"""What a config file may hold: its sections, their keys with types, defaults and comments, and how each
section becomes the frozen dataclass that validates it.

The sections map onto the dataclasses the code already runs with:

========== ============================================= =================================================
section    dataclass                                      keys
========== ============================================= =================================================
world      crowdsim.world.WorldFacts                      the facts the simulator and the MPC share
env        crowdsim.env.EnvConfig                         the simulator's conventions (a named profile's)
env.orca   crowdsim.orca.OrcaParams                       the humans' ORCA
scenario   pipelines.config.settings.ScenarioSettings     simulate's scenario, crowd and robots
controller pipelines.config.settings.ControllerSettings   pipelines.loop.spec.ControllerSpec's choices
mpc        mpc.config.MPCConfig                           Table I, the solver (ControllerSpec.mpc_overrides)
simulate   pipelines.config.settings.SimulateSettings     ``crowdmpc simulate``'s run
sweep      pipelines.config.settings.SweepSettings        ``crowdmpc sweep``'s run
========== ============================================= =================================================

``[world]`` is the one place for tau, L, the radius and the speed bounds: it reaches the simulator through
``EnvConfig.from_world`` and the MPC through ``MPCConfig.from_world``, so ``[env]`` and ``[mpc]`` refuse
those keys. ``[mpc]`` also refuses ``human_margins`` (margins are ``[controller] margins``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import fields
from typing import Any, Final

from crowdsim.env import EnvConfig
from crowdsim.orca import OrcaParams
from crowdsim.profiles import PROFILES, make_env_config
from crowdsim.scenarios import MAX_HUMANS, MAX_ROBOTS
from crowdsim.world import PAPER_ROBOTS, WorldFacts
from mpc.config import MPCConfig
from pipelines.config.keys import MOST, Key, Section, keys_of, kind_of
from pipelines.config.notes import ENV_NOTES, MPC_NOTES, ORCA_NOTES, WORLD_NOTES
from pipelines.config.settings import (
    ControllerSettings,
    ScenarioSettings,
    SimulateSettings,
)
from pipelines.config.sweep_keys import build_sweep, sweep_keys

# ---- [world] ---------------------------------------------------------------------------------------------
WORLD_KEYS: Final = keys_of(WorldFacts(), tuple(f.name for f in fields(WorldFacts)), WORLD_NOTES, "world")


def _build_world(values: dict[str, Any], built: Mapping[str, Any]) -> WorldFacts:
    return WorldFacts(**values)


# ---- [env.orca] ------------------------------------------------------------------------------------------
ORCA_KEYS: Final = keys_of(OrcaParams(), tuple(f.name for f in fields(OrcaParams)), ORCA_NOTES, "env.orca")


def _build_orca(values: dict[str, Any], built: Mapping[str, Any]) -> OrcaParams:
    return OrcaParams(**values)


# ---- [env] -----------------------------------------------------------------------------------------------
# EnvConfig's fields that [world] sets (history_len is the world's obs_len); its ORCA is [env.orca].
ENV_FROM_WORLD: Final[tuple[str, ...]] = ("dt", "history_len", "radius", "v_pref", "v_max", "a_max")
# The profile's conventions: unset, they are the chosen profile's values.
ENV_PROFILE_KEYS: Final[tuple[str, ...]] = (
    "time_limit",
    "timeout_margin",
    "spawn_separation",
    "crossing",
    "success_rule",
    "orca_radius_margin",
)


def _profile_note(name: str) -> str:
    values = ", ".join(f"{p} {getattr(cfg, name)!r}" for p, cfg in sorted(PROFILES.items()))
    return f"{ENV_NOTES[name]}; unset: the profile's ({values})"


ENV_KEYS: Final[tuple[Key, ...]] = (
    Key(
        "profile",
        "str",
        "paper",
        "simulation conventions: paper (the authors' CrowdNav fork) | v1 (this project's first simulator); "
        "the keys left unset below take its values (--profile)",
    ),
    Key("robots_visible", "bool", True, "the humans' ORCA sees the robots (--visibility visible|invisible)"),
    Key("goal_assignment", "str", "fixed", "fixed (robot i to goal i, paper) | slots (crowdsim/slots.py)"),
    Key(
        "formation",
        "str",
        "auto",
        "the robots' starts and goals: auto (a row up to 3 robots, a wedge from 4) | row | wedge | two_rows "
        "| antipodal (robots trading places across a 3.5 m circle; crowdsim/scenarios.py)",
    ),
    Key(
        "robot_spacing",
        "float",
        None,
        "m between neighbouring robots and between their goals; unset: the formation's own (the row 1 m, the "
        "others d_ij = 1.2 m); wider where the MPC's d_min keeps robots from standing on goals that close",
        1.2,
    ),
    Key(
        "crowd",
        "str",
        "orca",
        "the humans: orca (simulated, the paper's) | eth | hotel | eth_test | hotel_test (BIWI's pedestrians "
        "replayed, not reacting; _test: the TrajNet++ test split alone; crowdsim/replay.py), each also "
        "_reactive (yielding to the robots: crowdsim/reaction.py) (--crowd)",
    ),
    *(
        Key(
            name,
            kind_of(getattr(EnvConfig(), name)),
            None,
            _profile_note(name),
            getattr(EnvConfig(), name),
            MOST.get(f"env.{name}"),
        )
        for name in ENV_PROFILE_KEYS
    ),
)


def _build_env(values: dict[str, Any], built: Mapping[str, Any]) -> EnvConfig:
    base = make_env_config(values["profile"], "visible" if values["robots_visible"] else "invisible")
    settings = {
        f.name: getattr(base, f.name) for f in fields(EnvConfig) if f.name not in (*ENV_FROM_WORLD, "orca")
    }
    settings |= {name: values[name] for name in ENV_PROFILE_KEYS if values[name] is not None}
    chosen = ("robots_visible", "goal_assignment", "formation", "robot_spacing", "crowd")
    settings |= {name: values[name] for name in chosen}
    return EnvConfig.from_world(built["world"], orca=built["env.orca"], **settings)


# ---- [scenario] ------------------------------------------------------------------------------------------
SCENARIO_KEYS: Final = (
    Key("name", "str", "circle", "circle | perpendicular (--scenario)"),
    Key("humans", "int", 7, f"humans in the crowd, 0..{MAX_HUMANS} (--humans)"),
    Key("robots", "int", PAPER_ROBOTS, f"robots, 1..{MAX_ROBOTS} (--robots; sweep too)"),
)


def _build_scenario(values: dict[str, Any], built: Mapping[str, Any]) -> ScenarioSettings:
    return ScenarioSettings(**values)


# ---- [controller] ----------------------------------------------------------------------------------------
CONTROLLER_KEYS: Final = (
    Key(
        "controller",
        "str",
        None,
        "straight | orca | cmpc (Algorithm 1) | dmpc (Algorithm 2) (--controller; simulate needs one; "
        "sweep: every method's)",
        "cmpc",
    ),
    Key(
        "predictor",
        "str",
        None,
        "a registered predictor or a zoo model (--predictor); unset: constant_velocity in simulate, "
        "the experiment's own in sweep",
        "constant_velocity",
    ),
    Key("coupling", "str", "ibr", "ibr (Alg. 1, 2) | nlp (predictor in the NLP) | none (robots unseen)"),
    Key("flocking", "bool", True, "false: omega^floc = 0 (Table III, NF; --no-flocking)"),
    Key(
        "margins",
        "str",
        None,
        "robot-human allowance for prediction error: none (the paper) | conformal[:ALPHA[:closed-loop|real]] "
        "| conformal-motion[:ALPHA] | conformal-shortfall[:ALPHA] | fixed:M1,..,MH (--margins); unset: none "
        "in simulate, the experiment's own in sweep",
        "none",
    ),
    Key(
        "record_iterations",
        "bool",
        False,
        "record every IBR iteration's prediction in the --record files (cmpc, dmpc; --record-iterations)",
    ),
)


def _build_controller(values: dict[str, Any], built: Mapping[str, Any]) -> ControllerSettings:
    return ControllerSettings(**values)


# ---- [mpc] -----------------------------------------------------------------------------------------------
MPC_FROM_WORLD: Final[tuple[str, ...]] = ("dt", "v_max", "a_max")
MPC_EXCLUDED: Final[tuple[str, ...]] = (*MPC_FROM_WORLD, "human_margins")
MPC_KEYS: Final = keys_of(
    MPCConfig(), tuple(f.name for f in fields(MPCConfig) if f.name not in MPC_EXCLUDED), MPC_NOTES, "mpc"
)


def _build_mpc(values: dict[str, Any], built: Mapping[str, Any]) -> MPCConfig:
    return MPCConfig.from_world(built["world"], **values)


# ---- [simulate] and [sweep] ------------------------------------------------------------------------------
SIMULATE_KEYS: Final = (
    Key("episodes", "int", 1, "episodes; episode i uses seed + i (--episodes)"),
    Key("seed", "int", 0, "the first episode's seed (--seed)"),
    Key(
        "json",
        "str",
        None,
        "write the summary and per-episode records here (--json; - is standard output; a leading ~ is the "
        "home directory)",
        "runs/run.json",
    ),
    Key(
        "plot",
        "str",
        None,
        "draw the first episode: PNG, PDF or SVG (--plot; ~ as for json)",
        "runs/episode.png",
    ),
    Key(
        "record",
        "str",
        None,
        "one MCAP file per episode in this folder (--record; ~ as for json)",
        "runs/mcap",
    ),
    Key("progress", "bool", True, "a progress bar on a terminal (--no-progress: none)"),
    Key(
        "sensor_range",
        "float",
        None,
        "m, 1e-06 to 1000: the controller sees only the humans within this distance of some robot, each from "
        "when it came into view, as a tracker gives them (pipelines/loop/sensing.py; --sensor-range; a sweep "
        "puts every method behind it); unset: every human",
        3.0,
    ),
    Key(
        "sensor_tracks",
        "bool",
        True,
        "with sensor_range: the tracker reports its track lengths, from which the MPC fills a late arrival's "
        "past (--no-sensor-tracks)",
    ),
)


def _build_simulate(values: dict[str, Any], built: Mapping[str, Any]) -> SimulateSettings:
    return SimulateSettings(**values)


_WORLD_REASON = "set it in [world], the one source of the simulator's and the MPC's shared facts"
SECTIONS: Final[tuple[Section, ...]] = (
    Section(
        "world",
        "The facts the simulator, the MPC and the predictors share (crowdsim/world.py). Set here only: they "
        "reach the simulator through EnvConfig.from_world and the MPC through MPCConfig.from_world.",
        WORLD_KEYS,
        _build_world,
    ),
    Section(
        "env.orca",
        "The humans' ORCA (crowdsim/orca.py, OrcaParams): RVO2's parameters as CrowdNav sets them.",
        ORCA_KEYS,
        _build_orca,
    ),
    Section(
        "env",
        "The simulator (crowdsim/env_config.py, EnvConfig): a named profile's conventions, each overridable.",
        ENV_KEYS,
        _build_env,
        {
            **{name: _WORLD_REASON for name in ENV_FROM_WORLD if name != "history_len"},
            "history_len": "set [world] obs_len, the one source of the observed steps",
        },
    ),
    Section(
        "scenario",
        "What simulate runs (crowdsim/scenarios.py); a sweep reads robots and refuses the others (its "
        "episodes alternate the two scenarios, its crowd sizes are [sweep] humans).",
        SCENARIO_KEYS,
        _build_scenario,
    ),
    Section(
        "controller",
        "The robots' controller (pipelines/loop/spec.py, ControllerSpec). A sweep applies what is set here, "
        "or differs from these defaults, to every method of its experiment.",
        CONTROLLER_KEYS,
        _build_controller,
    ),
    Section(
        "mpc",
        "The MPC of cmpc and dmpc (mpc/config.py, MPCConfig): the paper's Table I, the two values it omits, "
        "and the solver. Values that differ from these defaults become ControllerSpec.mpc_overrides (and "
        "part of a sweep's cell keys).",
        MPC_KEYS,
        _build_mpc,
        {
            **{name: _WORLD_REASON for name in MPC_FROM_WORLD},
            "human_margins": 'set margins in [controller] margins (e.g. "fixed:0.05,0.1,0.15,0.2")',
        },
    ),
    Section(
        "simulate",
        "crowdmpc simulate's run. A sweep reads sensor_range and sensor_tracks here and passes the others "
        "over in a file (one file may serve both; --set refuses them for a sweep): its own are in [sweep].",
        SIMULATE_KEYS,
        _build_simulate,
    ),
    Section("sweep", "crowdmpc sweep's run (pipelines/experiments).", sweep_keys(), build_sweep),
)
SECTION_BY_NAME: Final[Mapping[str, Section]] = {s.name: s for s in SECTIONS}


def key_default(section: str, key: str) -> Any:
    """``section.key``'s default as the schema holds it, for a help text that states it: read here, the text
    cannot drift from the value (a literal in the help could). KeyError for a key the schema has not."""
    found = SECTION_BY_NAME[section].key(key)
    if found is None:
        raise KeyError(f"{section}.{key}")
    return found.default


# The order in which sections are written: a nested table follows its parent.
WRITE_ORDER: Final[tuple[str, ...]] = (
    "world",
    "env",
    "env.orca",
    "scenario",
    "controller",
    "mpc",
    "simulate",
    "sweep",
)
