"""A sweep's recorded config, back as a ``RunConfig``: ``crowdmpc config show --from-sweep DIR`` prints the
TOML that reruns what a sweep directory holds (each run line of ``sweep.json`` keeps the effective config it
ran with, ``RunConfig.effective``, and the code it ran: ``pipelines.plugins.code_with_plugins``).

The recorded values go through the same resolver as a config file's (unknown sections and keys, types and
bounds refused, naming ``sweep.json``), so what comes out loads back to the same run. A null of a key that
takes inf (``INFINITE_KEYS``) is inf, which the JSON record cannot hold. Three values are not written as
recorded: the [env] values that are the recorded profile's own stay unset, as a file leaves a
default out (another ``--profile`` then takes its own), unless a cell of another profile ran with them,
``[sweep] out`` is the directory read, absolute, and a value refused now where typed (a margins spec
``conformal:``, a [simulate] path "none") is written as it ran.
This machine's limit on local workers is not applied (the sweep that runs the file applies it): a comment
says when the recorded workers exceed it.
"""

from __future__ import annotations

import math
import shlex
import textwrap
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

from pipelines.config.entries import ConfigError, Entry, Source, check_key, parse_set
from pipelines.config.resolve import RunConfig, resolve
from pipelines.config.schema import ENV_PROFILE_KEYS, SECTION_BY_NAME
from pipelines.config.settings import LOCAL_WORKERS_PER_CPU, available_cpus, local_workers_limit

if TYPE_CHECKING:
    from pipelines.config.command_line import Option

# The keys that take inf (OrcaParams: every agent a neighbour, velocity obstacles never truncated), which a
# record writes as null, JSON having no inf: read as unset, a sweep run with one was shown and reported as
# one of the default 10 m or 5 s, whose cells the folder does not hold. Their default is a number, so a
# recorded null is no unset value.
INFINITE_KEYS: Final[tuple[tuple[str, str], ...]] = (
    ("env.orca", "neighbor_dist"),
    ("env.orca", "time_horizon"),
)


def recorded_runs(directory: str | Path) -> tuple[Path, list[dict[str, Any]]]:
    """``(sweep.json's path, its run lines)``; ConfigError when ``directory`` holds no sweep."""
    from pipelines.experiments.log import SWEEP_FILE, read_sweep_file

    if str(directory) == "":  # Path("") is ".": the current directory, which was not given
        raise ConfigError("--from-sweep must be a sweep directory, got ''")
    path = Path(directory) / SWEEP_FILE
    if Path(directory).name == SWEEP_FILE and Path(directory).is_file():  # the file named for its folder
        raise ConfigError(
            f"--from-sweep {directory}: that is a sweep's file; give its folder, {path.parent.parent}"
        )
    if path.exists() and not path.is_file():  # a folder or a pipe of that name is no missing file
        raise ConfigError(
            f"--from-sweep {directory}: {path} is not a regular file (a folder, a device or a pipe)"
        )
    if not path.is_file():
        raise ConfigError(f"--from-sweep {directory}: no {SWEEP_FILE} (not a sweep directory)")
    runs = [r for r in read_sweep_file(path).get("runs", []) if isinstance(r, dict)]
    if not runs:
        raise ConfigError(f"--from-sweep {directory}: {path} records no run")
    return path, runs


def recorded_config(path: Path, run: dict[str, Any], index: int) -> RunConfig:
    """The config run ``index`` (1-based) of ``path`` recorded, resolved as a config file would be, with
    ``[sweep] out`` the directory that holds ``path``."""
    where = f"{path} (run {index})"
    return resolve(recorded_entries(path, run, index), where)


def report_config(args: Any, options: Sequence[Option]) -> RunConfig:
    """``sweep --report-only``'s config: the sweep's own, as the last run line of its sweep.json recorded
    it, beneath the --set items and options typed, when no --config file is given (a report of a sweep run
    with --predictor, --margins or --crowd asked for them again, or found none of its records); else, or
    for a sweep from before configs were kept, the command line's alone (``command_config``)."""
    from pipelines.config.command_line import cli_entries, command_config, config_arguments
    from pipelines.experiments.log import SWEEP_FILE

    typed = command_config(args, options)  # checked as it stands first: a typo is named as typed
    path, sets = config_arguments(args)
    held = None if typed.sweep.out is None else Path(typed.sweep.out) / SWEEP_FILE
    # a link is not read: the sweep's checks refuse it as they refuse one in a run (nothing read first)
    if path is not None or held is None or held.is_symlink() or not held.is_file():
        return typed
    try:
        sweep_file, runs = recorded_runs(held.parent)
    except ConfigError:  # no run line yet (a sweep stopped before its first): the typed plan, as before
        return typed
    from pipelines.experiments.run_lines import is_reused

    last = last_own_run(runs)
    if not isinstance(runs[last - 1].get("config"), dict) or is_reused(runs[last - 1]):
        return typed
    entries = recorded_entries(sweep_file, runs[last - 1], last)
    entries += [parse_set(text) for text in sets] + list(cli_entries(args, options))
    return resolve(entries, f"{sweep_file} (run {last})")


def ran_beyond_bound(directory: Path, section: str, key: str, value: Any) -> str:
    """The words ("" for none) a refusal of ``value`` adds when a sweep's own run in ``directory`` recorded
    it: that folder ran before the bound refusing it now, and its report still reads back (the refusal alone
    sent a rerun or --reuse of it to look for a typo, as if the folder held no such run), as its own setting
    or a --vary column's (``_ran_values``). ``section`` as a record names it: ``env.orca`` is one of its own
    there (``RunConfig.effective``), not nested in ``env``."""
    from pipelines.experiments.run_lines import own_runs

    try:
        _, runs = recorded_runs(directory)
    except ConfigError:  # no sweep there: the refusal as for any run
        return ""
    for index in own_runs(runs):
        if value in _ran_values(runs[index - 1].get("config"), section, key):
            return (
                f"; {directory} ran with {section}.{key} = {value!r} before that bound: no more of it runs, "
                f"and `crowdmpc sweep --report-only --out {shlex.quote(str(directory))}` still reports it"
            )
    return ""


def _ran_values(values: Any, section: str, key: str) -> list[Any]:
    """The values of ``section.key`` a run line's recorded config (``values``) ran with: its own, and each of
    a --vary column's, which the record keeps only as typed in [sweep] vary (``simulate.sensor_range=3,2000``,
    ``mpc.w_goal=1,1e-60``): a rerun of that sweep was refused a column's value in the bound's words alone.
    A damaged or foreign value is no value (the refusal is then as for any run)."""
    if not isinstance(values, dict):
        return []
    own, sweep = values.get(section), values.get("sweep")
    ran = [own.get(key)] if isinstance(own, dict) else []
    vary = sweep.get("vary") if isinstance(sweep, dict) else None
    for part in vary.split(";") if isinstance(vary, str) else ():
        name, equals, items = part.partition("=")
        if equals and name.strip() == f"{section}.{key}":
            for item in items.split(","):
                try:  # read as the sweep read it (sweep_vary's parse_set), so 2000 is the 2000.0 refused
                    ran.append(parse_set(f"{section}.{key}={item}").value)
                except ConfigError:
                    continue
    return [item for item in ran if item is not None]  # null: unset, no column (sweep_vary refuses it)


def ran_beyond_bound_in(folders: Iterable[Path | None], section: str, key: str, value: Any) -> str:
    """``ran_beyond_bound``'s words for the first of ``folders`` (the sweep folders a run would add to or
    take from, --out and --reuse; None: not given) whose sweep ran ``value``, "" for none."""
    notes = (ran_beyond_bound(folder, section, key, value) for folder in folders if folder is not None)
    return next((note for note in notes if note), "")


def last_own_run(runs: list[dict[str, Any]]) -> int:
    """The number (from 1) of the last run line that is a run of the sweep itself, not the code of episodes
    ``sweep --reuse`` took (pipelines.experiments.reuse); the last line when none is."""
    from pipelines.experiments.run_lines import own_runs

    return (own_runs(runs) or [len(runs)])[-1]


def recorded_entries(path: Path, run: dict[str, Any], index: int) -> list[Entry]:
    """The entries of the config run ``index`` of ``path`` recorded (``recorded_config``)."""
    from pipelines.experiments.run_lines import REUSED, is_lost, is_reused

    where = f"{path} (run {index})"
    values = run.get("config")
    if is_reused(run):  # another sweep's run, of another experiment and folder
        raise ConfigError(
            f"{where} is run {run.get('run_there')} of {run[REUSED]}, whose episodes this sweep took with "
            f"--reuse: `crowdmpc config show --from-sweep {shlex.quote(str(run[REUSED]))} --run "
            f"{run.get('run_there')}` prints what it ran"
        )
    if is_lost(run):  # run_lines.lost_runs: the run's line was gone when a later run began
        raise ConfigError(f"{where} was lost from the file ({run['lost']}): its config is unknown")
    if not isinstance(values, dict):
        raise ConfigError(f"{where} records no config{_why_no_config(path)}")
    source = Source("file", where)
    own = _profile_values(values, run)
    entries: list[Entry] = []
    for name, section in values.items():
        if name == "config_file":  # where the values came from, not a value
            continue
        if name not in SECTION_BY_NAME:
            raise ConfigError(f"{where}: unknown config section {name!r}; the file is damaged")
        if not isinstance(section, dict):  # a known section: "unknown" sent the reader to look for a typo
            raise ConfigError(f"{where}: config section {name!r} is not a table of keys; the file is damaged")
        for key, value in section.items():
            check_key(source.prefix(name, key), SECTION_BY_NAME[name], key)
            if value is None and (name, key) in INFINITE_KEYS:  # a record writes inf as null (plain_json)
                value = math.inf
            # null: unset, as a file leaves it out. The profile's own value: unset too (a record holds every
            # [env] value, RunConfig.effective), or the file would hold the paper profile's time limit,
            # crossing ... under --profile v1, and a sweep of it would be refused them; unless a cell ran
            # with it (_profile_values).
            if value is not None and not (name == "env" and key in own and own[key] == value):
                entries.append(Entry(name, key, _as_ran(name, key, value), source))
    # The recorded out may be relative to wherever that sweep started; this directory is where it resumes.
    entries.append(Entry("sweep", "out", str(Path(path).parent.resolve()), source))
    return entries


def _as_ran(section: str, key: str, value: Any) -> Any:
    """A recorded value that is refused now where it is typed, written as the code that ran it read it, so
    that a sweep run with one can still be reported: a margins spec (``[controller] margins``, or in ``[sweep]
    vary``) with an empty alpha or source (``conformal:``, ``conformal::real``, ``none:``) ran at the
    default; a [simulate] path "none" or "null" (a config file's, which a sweep records too) was a file."""
    if (section, key) == ("controller", "margins") and isinstance(value, str):
        return _margins_as_ran(value)
    if section == "simulate" and key in ("json", "plot", "record") and str(value).lower() in ("none", "null"):
        return f"./{value}"  # the file it wrote (the word is refused now: meant as off)
    if (section, key) == ("sweep", "vary") and isinstance(value, str):
        parts = []
        for part in value.split(";"):
            name, equals, items = part.partition("=")
            if equals and name.strip() == "controller.margins":  # a fixed margin's bare numbers: kept
                part = name + equals + ",".join(_margins_as_ran(item) for item in items.split(","))
            parts.append(part)
        return ";".join(parts)
    return value


def _margins_as_ran(text: str) -> str:
    from pipelines.loop.margins import CALIBRATED_MODES, DEFAULT_ALPHA

    mode, colon, rest = text.strip().partition(":")
    if not colon:
        return text
    if mode == "none" and not rest:
        return "none"
    alpha, _, source = rest.partition(":")
    if mode not in CALIBRATED_MODES or (alpha and source):
        return text
    return ":".join([mode, alpha or repr(DEFAULT_ALPHA), *([source] if source else [])])


def _profile_values(values: dict[str, Any], run: dict[str, Any]) -> dict[str, Any]:
    """The recorded profile's own values of the [env] keys it sets (none when that profile is unknown: the
    resolver refuses it, naming the file), but those the sweep asked for: a value some recorded cell ran
    with over its own profile's (``World.env_settings``), not by ``[sweep] vary``. `--set
    env.time_limit=40.0`, the paper's, gave the conventions experiment's v1 cells 40 s; left unset, a
    rerun and ``--report-only`` planned v1 cells of 30 s, whose episodes the folder does not hold."""
    from crowdsim.profiles import PROFILES

    env = values.get("env")
    default = next(k.default for k in SECTION_BY_NAME["env"].keys if k.name == "profile")  # none recorded
    name = env.get("profile", default) if isinstance(env, dict) else default
    profile = PROFILES.get(name) if isinstance(name, str) else None
    if profile is None:
        return {}
    sweep = values.get("sweep")
    vary = sweep.get("vary") if isinstance(sweep, dict) else None
    varied = {part.partition("=")[0].strip() for part in vary.split(";")} if isinstance(vary, str) else set()
    cells = run.get("cells")
    ran = [
        tuple(pair)
        for cell in (cells if isinstance(cells, list) else [])
        for pair in (cell.get("env_settings") or [] if isinstance(cell, dict) else [])
        if isinstance(pair, list) and len(pair) == 2 and f"env.{pair[0]}" not in varied
    ]
    own = {key: getattr(profile, key) for key in ENV_PROFILE_KEYS}
    return {key: value for key, value in own.items() if (key, value) not in ran}


def provenance(path: Path, run: dict[str, Any], index: int, total: int) -> str:
    """Comment lines naming where the config came from and the code that ran it."""
    recorded = run.get("code")
    code: dict[str, Any] = recorded if isinstance(recorded, dict) else {}
    commit = _plain(code.get("commit") or "not recorded")
    dirty = " with uncommitted changes" if code.get("dirty") else ""
    return (
        f"# From {path}, run {index} of {total} (started {_plain(run.get('started', '?'))}), crowdmpc "
        f"{_plain(run.get('version', '?'))} at commit {commit}{dirty}.\n"
        "# Its [sweep] out is that directory, where a rerun resumes; give --out NEW to rerun elsewhere.\n"
        f"{_plugins_note(code.get('plugins'))}"
    )


def _plugins_note(recorded: object) -> str:
    """Comment lines naming the plugins a run's code held (``code.plugins``: ``module:Class`` -> sha256), as
    the --plugin options a rerun needs: the file names none, and a sweep of it alone stopped on the first
    predictor or controller of a plugin's ("a plugin that is not registered")."""
    from pipelines.loop.spec import is_plugin_spec

    specs = sorted(spec for spec in recorded if is_plugin_spec(spec)) if isinstance(recorded, dict) else []
    if not specs:
        return ""
    options = " ".join(f"--plugin {spec}" for spec in specs)
    return comment(f"It ran plugins' code: rerun it as `crowdmpc {options} --config FILE sweep --out NEW`.")


def machine_note(config: RunConfig) -> str:
    """Comment lines when the recorded workers are more than a local pool takes on this machine: the record
    reads back anywhere, and a sweep of the printed file here refuses them
    (``SweepSettings.beyond_this_machine``)."""
    if config.sweep.beyond_this_machine() is None:
        return ""
    text = (
        f"Its [sweep] workers = {config.sweep.workers} is more than a local pool takes on this machine (at "
        f"most {local_workers_limit()}: {LOCAL_WORKERS_PER_CPU} per CPU this process may use, "
        f"{available_cpus()}); give --workers N, or edit it, to rerun here."
    )
    return comment(text)


def comment(text: str) -> str:
    """``text`` as TOML comment lines of the printed file's width ("" for none)."""
    return "".join(f"# {line}\n" for line in textwrap.wrap(text, 106))


def _plain(value: Any) -> str:
    """A recorded value inside a comment: one short line (a line break in it would end the comment, and what
    follows would be read as TOML)."""
    return " ".join(str(value).split())[:80]


def _why_no_config(path: Path) -> str:
    """Why a run line of ``path`` holds no config, and what reruns it: a sweep's run line has held it since
    configs were kept, but ``run_sweep`` called from Python records none (its ``SweepConfig`` has no
    ``run_config``), and its experiment may be one no --experiment names (docs/examples/own_experiment.py),
    where "rerun it from its options" sent the reader to options that cannot name it."""
    from pipelines.experiments.cells import EXPERIMENTS
    from pipelines.experiments.log import read_sweep_file

    experiment = read_sweep_file(path).get("experiment")
    if isinstance(experiment, str) and experiment not in EXPERIMENTS:
        return (
            f": its experiment {experiment!r} is no --experiment but an Experiment swept from Python, with "
            "run_sweep, which records no config; rerun it with the code that swept it"
        )
    return (
        " (a sweep from before configs were kept, or one swept from Python with run_sweep, which records "
        "none); rerun it from its options"
    )
