"""Runs (sweeps, simulate --json files, MCAP recordings) compared on the crowds they share: each run's
success, collision, contact, discomfort and travel time per method and crowd size, and each run against the
first, episode by episode (``crowdmpc compare``).

Which episodes pair. Two runs face the same crowd when they ran the same scenario from the same seed with the
same number of humans and robots, and the crowd was made alike: ORCA's humans or the same replayed recording
(``env.crowd``; a replay's reactive replay draws the same people, who then yield to the robots), placed
under the same rules (``env.crossing``, ``env.spawn_separation``) around the same robot formation
(``env.formation``, ``env.robot_spacing``; the placement keeps clear of the robots' starts: crowdsim
.scenarios).
Another profile or team draws other humans from the same seed, so its episodes pair with none. A record made
before sweeps kept their config ran its profile's placement. Within that crowd an episode is its method's
(case ignored: Table II writes "CMPC", the controllers experiment "cmpc"), so a method's column of one sweep
pairs with the same method's of another whatever else the two changed (margins, weights, code): the
comparison is what the runs differ in, listed beside it (``settings_differ``); or, for sweeps by cell
(``--by-cell``), its cell's, whatever the column's label. Only episodes every run holds are compared.

The paired counts are the exact McNemar test's discordant pairs (pipelines.experiments.paired): episodes where
the run has the outcome and the first run not, and the reverse. The difference of the two rates has Newcombe's
square-and-add 95 % interval for paired proportions (pipelines.experiments.paired), which unlike the normal
approximation stays inside [-100, 100] % and is not of zero width at 0 of n. Discomfort is one of these flags:
the paper's discomfort rate is the % of episodes in which some robot's projected path crossed a human's, each
episode's yes or no, so it pairs as collision does (its per-step frequency is the sweep's cells.csv's). Travel
time is compared on the episodes both runs completed, as the mean of the differences with Student's t 95 %
half-width, as cells.csv gives a mean's. Each describes one group; none is corrected for the number of groups
compared.
"""

from __future__ import annotations

import hashlib
import json
import sys
from collections.abc import Collection, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

from crowdsim.metrics import ADDED_FIELDS
from pipelines.errors import PipelineError
from pipelines.experiments.compare_sources import recording_records, simulate_records, sweep_records
from pipelines.experiments.log import EPISODES_FILE
from pipelines.experiments.paired import FLAGS, Outcome
from pipelines.logs.identity import NOT_SETTINGS, UNRECORDED_DEFAULTS, dotted_settings
from pipelines.logs.reader import UNFINISHED_SUFFIX, find_recordings
from pipelines.loop.replay_data import REACTIVE_SUFFIX
from pipelines.loop.unread import record_unread
from predictors.progress import progress_bar

# The simulator settings besides scenario, seed and team that decide an episode's crowd (module docstring).
CROWD_SETTINGS: Final = ("crowd", "crossing", "spawn_separation", "formation", "robot_spacing")
# Record fields beyond its config that tell what ran (wall time, worker and key differ in any two runs).
RUN_FIELDS: Final[tuple[str, ...]] = (
    "predictor",
    "predictor_sha256",
    "crowd_sha256",
    "sensor_range",
    "sensor_tracks",
)

SOURCES: Final = "a sweep folder, a simulate --json file, or recordings: an .mcap file or a folder of them"
Group = tuple[str, int, int]  # method (case folded), humans, robots
Identity = tuple[Any, ...]  # Group + scenario, seed and the crowd's settings


@dataclass
class Run:
    """One sweep directory as the comparison reads it."""

    label: str
    path: Path
    outcomes: dict[Identity, Outcome] = field(default_factory=dict)
    methods: dict[Group, str] = field(default_factory=dict)  # each group's method as this run spells it
    # with --by-cell, each group's cell key as this run spells it (its group holds it case folded)
    cells: dict[Group, str] = field(default_factory=dict)
    # per group, each dotted setting -> the values its episodes ran with
    settings: dict[Group, dict[str, set[str]]] = field(default_factory=dict)
    # per group, the [mpc] keys some of its episodes' controller does not read (pipelines.loop.unread)
    unread: dict[Group, set[str]] = field(default_factory=dict)
    commits: list[str] = field(default_factory=list)
    # a sweep's groups (case folded method, or cell with --by-cell) in its sweep.json plan's order, whatever
    # order its parallel workers finished them in; empty for other runs, whose order is their episodes'
    plan: dict[str, int] = field(default_factory=dict)


def crowd_identity(record: Mapping[str, Any], by_cell: bool = False) -> Identity:
    """The episode's identity across runs (module docstring). A record older than a setting ran with the
    value every run had before it (``UNRECORDED``), one older than the recorded config with its profile's.
    ``by_cell``: a sweep's episode is its cell's (``cell``, the key that names everything that makes its
    episodes), not its method label's: a --vary column pairs with the plain sweep's column of that cell."""
    name = record["cell"] if by_cell else record["method"]
    group: Group = (sys.intern(str(name).casefold()), int(record["n_humans"]), int(record["n_robots"]))
    config = record.get("config")
    env = config.get("env") if isinstance(config, dict) else None
    if not isinstance(env, dict):
        env = _profile_env(str(record.get("profile") or "paper"))
    values = {name: env.get(name, UNRECORDED.get(name)) for name in CROWD_SETTINGS}
    if isinstance(values["crowd"], str):  # a replay and its reactive replay draw the same people from a seed
        values["crowd"] = values["crowd"].removesuffix(REACTIVE_SUFFIX)
    # interned: the same few strings in every identity, not a copy each (a million records a run)
    crowd = tuple(sys.intern(json.dumps(values[name], sort_keys=True)) for name in CROWD_SETTINGS)
    return (*group, sys.intern(str(record["scenario"])), int(record["seed"]), *crowd)


# The crowd settings added after sweeps began to record their config, as every episode before ran them: the
# recordings' own list (pipelines.logs.identity), whose "env." keys are a record's config's "env" keys.
UNRECORDED, UNRECORDED_MPC = (
    {k.removeprefix(p): v for k, v in UNRECORDED_DEFAULTS.items() if k.startswith(p)}
    for p in ("env.", "mpc.")
)


def _profile_env(profile: str) -> dict[str, Any]:
    from crowdsim.profiles import PROFILES, make_env_config

    if profile not in PROFILES:
        return {"profile": profile}  # pairs with nothing but its own kind
    env = make_env_config(profile, "visible")
    return {"crossing": env.crossing, "spawn_separation": env.spawn_separation}


def load_run(label: str, path: Path, progress: bool | None = False, by_cell: bool = False) -> Run:
    """The episodes of the sweep directory ``path``, read as its report reads them (each line checked) and
    left as they are (a sweep still writing it may hold a torn last line, which is passed over); or of the
    ``crowdmpc simulate --json`` file ``path``, or of the recordings ``path`` (an .mcap file, or a folder of
    them), each episode its controller's (pipelines.experiments.compare_sources). ``progress``: a bar of the
    episodes or files read (None: on a terminal only; a run of 100 000 takes about 17 s). ``by_cell``:
    ``crowd_identity``'s, for sweeps alone."""
    if path.name == EPISODES_FILE and path.is_file():  # the sweep's log named instead of its folder
        path = path.parent
    if by_cell and not (path / EPISODES_FILE).is_file():
        raise PipelineError(f"{label}: {path} is no sweep folder: --by-cell pairs sweeps' episodes by cell")
    records, commits, cells, twice = _source(label, path, progress)
    run = Run(label, path, commits=commits)
    kinds: dict[frozenset[str], frozenset[str]] = {}  # one ``added`` set per kind of record, not per episode
    configs: set[tuple[Group, str]] = set()
    bar = progress_bar(
        records, show=progress, desc=f"reading {label}", unit="ep", file=sys.stderr, leave=False
    )
    for record in bar:
        identity = crowd_identity(record, by_cell)
        if identity in run.outcomes:
            raise PipelineError(
                f"{label}: {path} holds two episodes of method {record['method']!r} on one crowd "
                f"({run.outcomes[identity].key} and {record['key']}): {twice}"
            )
        run.outcomes[identity] = _outcome(record, kinds)
        run.methods.setdefault(identity[:3], str(record["method"]))
        if by_cell:
            run.cells.setdefault(identity[:3], str(record["cell"]))
        ran = {"config": _with_unrecorded(record.get("config")), **_run_fields(record)}
        text = json.dumps(ran, sort_keys=True)
        if (identity[:3], text) in configs:  # a cell's episodes share their settings: flattened once
            continue
        configs.add((identity[:3], text))
        ran_with = run.settings.setdefault(identity[:3], {})
        run.unread.setdefault(identity[:3], set()).update(f"mpc.{key}" for key in record_unread(record))
        for key, value in dotted_settings(ran).items():
            setting = key.removeprefix("config.")
            if setting not in NOT_SETTINGS:  # where a calibration is stored, not what it is
                ran_with.setdefault(setting, set()).add(json.dumps(value, sort_keys=True))
    if not run.outcomes:
        log = path / EPISODES_FILE
        raise PipelineError(f"{label}: {log if log.is_file() else path} holds no episode")
    for cell in cells:  # read with the records
        name = cell.get("key" if by_cell else "method")
        if isinstance(name, str):
            run.plan.setdefault(name.casefold(), len(run.plan))
    return run


def _run_fields(record: Mapping[str, Any]) -> dict[str, Any]:
    """``RUN_FIELDS`` of ``record``; ``crowd_sha256`` only where it is recorded (a replayed crowd's record,
    or its simulate run's): ORCA's crowd, and files written before it was recorded, name no file, which is
    not null."""
    return {k: record.get(k) for k in RUN_FIELDS if k != "crowd_sha256" or k in record}


def _source(
    label: str, path: Path, progress: bool | None
) -> tuple[Iterable[dict[str, Any]], list[str], list[dict[str, Any]], str]:
    """``path``'s records, the commits that made them, the cells a sweep planned, and what to do when two
    share a crowd."""
    if path.is_file() and not path.name.endswith((".mcap", ".mcap" + UNFINISHED_SUFFIX)):
        records, commits = simulate_records(path)
        return records, commits, [], "its episodes repeat a crowd"
    if not path.exists():
        raise PipelineError(f"{label}: {path} does not exist ({SOURCES})")
    if path.is_dir() and (path / EPISODES_FILE).is_file():
        scanned, commits, cells = sweep_records(path)  # its commits and cells once every record is read
        return scanned, commits, cells, "its cells are not told apart by method (use --by-cell)"
    if path.is_dir() and (path / EPISODES_FILE).exists():  # a pipe or a folder: "holds no" misled
        raise PipelineError(f"{label}: {path / EPISODES_FILE} is not a regular file (a folder or a pipe)")
    if path.is_dir() and not _holds_recordings(path):
        raise PipelineError(
            f"{label}: {path} holds no {EPISODES_FILE} (a `crowdmpc sweep --out` folder has one) and no "
            ".mcap recordings"
        )
    records, commits = recording_records(path, label, progress)
    return records, commits, [], "compare each folder as a run of its own"


def _holds_recordings(folder: Path) -> bool:
    try:
        return bool(any(find_recordings(folder)))
    except PipelineError:
        return False


def _with_unrecorded(config: Any) -> dict[str, Any]:
    """A record's config with the crowd settings it predates at the value it ran with (``UNRECORDED``): a
    sweep recorded before ``robot_spacing`` existed ran with none, which is no difference from a new one's."""
    if not isinstance(config, dict):
        return {}
    env, mpc = config.get("env"), config.get("mpc")
    if isinstance(mpc, dict):  # likewise an [mpc] option added later at the value every run before had
        config = {**config, "mpc": {**UNRECORDED_MPC, **mpc}}
    if not isinstance(env, dict):
        return config
    return {**config, "env": {**UNRECORDED, **env}}


def _outcome(record: Mapping[str, Any], kinds: dict[frozenset[str], frozenset[str]]) -> Outcome:
    metrics = record["metrics"]
    success, collision, contact, discomfort = (bool(metrics.get(name)) for name in FLAGS)
    core = {k: v for k, v in metrics.items() if k not in ADDED_FIELDS}
    added = frozenset(metrics.keys() & ADDED_FIELDS)
    added = kinds.setdefault(added, added)
    travel = metrics.get("travel_time")
    digests = (_digest(metrics), _digest(core))
    return Outcome(success, collision, contact, discomfort, travel, record["key"], *digests, added)


def _digest(values: Mapping[str, Any]) -> bytes:
    return hashlib.blake2b(json.dumps(values, sort_keys=True).encode(), digest_size=16).digest()


def shared_identities(runs: list[Run]) -> list[Identity]:
    """The episodes every run holds, in the first run's order (its plan's: cells as its table lists them)."""
    others = [run.outcomes.keys() for run in runs[1:]]
    return [k for k in runs[0].outcomes if all(k in keys for keys in others)]


def groups_of(identities: list[Identity]) -> dict[Group, list[Identity]]:
    grouped: dict[Group, list[Identity]] = {}
    for identity in identities:
        grouped.setdefault(identity[:3], []).append(identity)
    return grouped


def settings_differ(base: Run, other: Run, groups: Collection[Group]) -> list[tuple[str, str, str]]:
    """(setting, the values the first run's episodes of ``groups`` ran with, the other's) where the two
    differ, each side its values joined with " | ", sorted; a setting one run does not record shows
    "(not recorded)". Only the groups compared: a method the other run lacks says nothing of it. The
    settings a user sets come first ("mpc.guidance"), the details under them after
    ("margins.calibration.created"). An [mpc] key that one side's controller does not read is none
    (``Run.unread``): it made no difference to that side's episodes, whatever value it records (a CMPC's
    DMPC update rule, the flocking weight of a run without flocking, whose ``flocking`` row says so)."""
    a_values, b_values = _settings(base, groups), _settings(other, groups)
    unread = set().union(*(run.unread.get(group, ()) for run in (base, other) for group in groups))
    rows = []
    for key in sorted(a_values.keys() | b_values.keys(), key=lambda k: (k.count("."), k)):
        a, b = a_values.get(key), b_values.get(key)
        if a != b and key not in unread:
            rows.append((key, _values(a), _values(b)))
    return rows


def _settings(run: Run, groups: Collection[Group]) -> dict[str, set[str]]:
    merged: dict[str, set[str]] = {}
    for group in groups:
        for key, values in run.settings.get(group, {}).items():
            merged.setdefault(key, set()).update(values)
    return merged


def _values(values: set[str] | None) -> str:
    return "(not recorded)" if values is None else " | ".join(sorted(values))
