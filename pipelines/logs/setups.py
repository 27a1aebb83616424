"""How ``crowdmpc review DIR`` tells a folder's runs apart: the runs by their set-up (``groups``), and each
set-up named by what tells it apart from the others (``named_settings``, ``group_parts``, ``short_names``)."""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

from pipelines.logs.identity import MISSING, RUN_IDENTITY, shown
from pipelines.logs.names import repeat_of
from pipelines.logs.review import commit_shown, count

if TYPE_CHECKING:
    from pipelines.logs.digest import RunDigest

# Runs pooled into one aggregate of a folder share their run_identity (pipelines.logs.recording), what tells
# runs apart when recording too (a CMPC run beside a straight-line one, or a row formation beside a wedge,
# is two results, not one average). A set-up is named by its RUN_IDENTITY values, then by the settings that
# tell it apart: these whenever they differ, any other only where these leave set-ups alike.
# margins.label ("none", "cp0.05", "cpm0.1") stands for the margins it made (mpc.human_margins, their mode).
NAMED_FIRST: Final[tuple[str, ...]] = (
    "env.crowd",
    "env.profile",
    "env.robots_visible",
    "env.formation",
    "margins.label",
)


@dataclass
class SetUp:
    """Runs of one folder that share their set-up."""

    identity: dict[str, Any] | None  # their run_identity; None: unknown (no readable episode metadata)
    members: list[RunDigest]


def identity_key(identity: Mapping[str, Any]) -> str:
    return json.dumps(identity, sort_keys=True, default=str)


def groups(runs: list[RunDigest]) -> list[SetUp]:
    """The runs by their set-up (``run_identity``: controller, predictor, crowd, and the simulator's and
    controller's settings of the "config" metadata), in the order of their first run. A run whose set-up is
    unknown (cut before its metadata, or metadata that does not parse) is no set-up of its own: with one
    known set-up it counts among its runs, as the folder's one aggregate always counted it."""
    by_key: dict[str, SetUp] = {}
    unknown: list[RunDigest] = []
    for run in runs:
        if run.identity is None:
            unknown.append(run)
            continue
        by_key.setdefault(identity_key(run.identity), SetUp(run.identity, [])).members.append(run)
    setups = list(by_key.values())
    if unknown and len(setups) == 1:
        setups[0].members = list(runs)  # every run, in the folder's order, as before
    elif unknown:
        setups.append(SetUp(None, unknown))
    return setups


def drop_repeats(setup: SetUp) -> dict[str, str]:
    """Leave each episode once among ``setup``'s members, and return each file left out -> the file kept in
    its place. An episode is its scenario and seed recorded by one code ("commit+dirty" and the plugins'
    files, or none recorded): a folder holding two copies of a run's files (a/ and a backup b/) pooled both,
    "collision 38.5 % (5/13)" where the ten episodes had 3. Of a seed one recorder was handed again (a gym
    loop resetting to it, its policy acting otherwise) each episode is its own, told by the repeat in its
    file's name (``names.repeat_of``): ``circle_seed000003_1.mcap`` was left out as a copy of
    ``circle_seed000003.mcap``, the policy's second episode uncounted. A run whose scenario or seed is
    unknown (cut before its metadata) is never a repeat. The copy kept is the first complete and undamaged
    one whose episode ended, else the first complete one, else the first whose episode ended, else the first
    (a killed run's file beside its rerun's; a copy with a bad chunk, whose lost solver steps the table's
    times left out, beside an intact one)."""
    kept: dict[tuple[Any, ...], RunDigest] = {}
    repeats: dict[str, str] = {}
    members = []

    def worse(run: RunDigest) -> tuple[bool, bool, bool]:
        damaged = run.problems_warning is not None  # the file's own problems or messages left out
        return run.summary["metrics"] is None, bool(run.summary["truncated"]), damaged

    for run in sorted(setup.members, key=worse):  # stable: in the folder's order among equals
        s = run.summary
        plugins = s.get("crowdmpc_plugins") or {}
        repeat = repeat_of(Path(run.file).name, s["scenario"], s["seed"])
        key = (s["scenario"], s["seed"], repeat, commit_shown(s), tuple(sorted(plugins.items(), key=str)))
        if s["scenario"] is None or s["seed"] is None or key not in kept:
            kept.setdefault(key, run)
            members.append(run)
        else:
            repeats[run.file] = kept[key].file
    order = {id(run): i for i, run in enumerate(setup.members)}
    setup.members = sorted(members, key=lambda r: order[id(r)])  # the folder's order, as before
    return repeats


def named_settings(setups: list[SetUp]) -> list[str]:
    """The settings beyond ``RUN_IDENTITY`` that name the set-ups: each of ``NAMED_FIRST`` whose value
    differs between the set-ups that record it, then, in the order they are recorded in, each other one that
    tells apart set-ups the ones before it did not (a profile's name stands for the settings that come with
    it)."""
    known = [s.identity for s in setups if s.identity is not None]

    def kinds(keys: list[str]) -> int:
        return len({tuple(identity_key({"v": i.get(k, MISSING)}) for k in keys) for i in known})

    def recorded_kinds(key: str) -> int:
        """Values among the set-ups that record ``key``: a controller that has no such setting (ORCA's
        margins) is told apart by its name, not by "margins not recorded"."""
        return len({identity_key({"v": i[key]}) for i in known if key in i})

    named = [key for key in NAMED_FIRST if recorded_kinds(key) > 1]
    keys = [*RUN_IDENTITY, *named]
    for key in dict.fromkeys(k for i in known for k in i if k not in keys):
        if kinds(keys) == len(known):
            break
        if kinds([*keys, key]) > kinds(keys):
            keys.append(key)
            named.append(key)
    return named


def setting(key: str, value: Any) -> str:
    """A setting in a set-up's name: "crowd eth", "formation row", "robots invisible", "mpc.horizon 8",
    "weights 0123456789ab"."""
    if value is MISSING:
        return f"{'margins' if key == 'margins.label' else key.removeprefix('env.')} not recorded"
    if key == "env.robots_visible" and isinstance(value, bool):
        return "robots visible" if value else "robots invisible"
    if key in ("env.crowd", "env.profile", "env.formation"):
        return f"{key.removeprefix('env.')} {shown(value)}"
    if key == "margins.label":
        return f"margins {shown(value)}"
    if key == "predictor_sha256" and isinstance(value, str):  # a name's two weights: the digits tell them
        return f"weights {value[:12]}"
    return f"{key} {shown(value)}"


def group_parts(setup: SetUp, named: list[str]) -> list[str]:
    """A set-up's name in parts: controller, predictor, crowd, then each named setting."""
    identity = setup.identity
    if identity is None:
        return ["set-up unknown (no readable episode metadata)"]
    return [
        str(identity.get("controller") or "-"),
        f"predictor {identity.get('predictor') or 'none'}",
        count(identity.get("n_robots"), "robot"),
        count(identity.get("n_humans"), "human"),
        *(setting(k, identity.get(k, MISSING)) for k in named),
    ]


def short_names(parts: list[list[str]]) -> list[str]:
    """Each set-up by what tells it apart from the others (the parts all of them share left out)."""
    shared = set.intersection(*(set(p) for p in parts))
    return [", ".join(x for x in p if x not in shared) or ", ".join(p) for p in parts]
