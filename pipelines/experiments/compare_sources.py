"""Where ``crowdmpc compare`` reads a run's episodes, and the code that made them: a sweep's log and
sweep.json, a ``crowdmpc simulate --json`` file, and MCAP recordings (``crowdmpc simulate --record DIR``,
``make demo``'s runs/demo/), each episode made into the record a sweep writes, its method the controller (a
sweep's "CMPC" column pairs with simulate's "cmpc").

A recording holds what simulate's JSON holds of its episode: the "/episode/metrics" message is the same
``EpisodeRecord`` and the "config" metadata the same effective config, so a folder of recordings compares with
the ``--json`` file of its run episode for episode, every metric equal. Only those two are read of each file
(``read_recording``'s ``topics``), not its hundreds of state messages."""

from __future__ import annotations

import json
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any, Final

from pipelines.errors import PipelineError, print_note
from pipelines.experiments.log import SWEEP_FILE, episode_log, read_sweep_file
from pipelines.experiments.run_lines import run_number, runs_named
from pipelines.version import CODE_VERSIONS, dirty_text, no_commit_text
from predictors.progress import progress_bar

METRICS_TOPIC: Final = "/episode/metrics"


def sweep_records(path: Path) -> tuple[Iterator[dict[str, Any]], list[str], list[dict[str, Any]]]:
    """The records of the sweep folder ``path``, read as its report reads them and left as they are (a sweep
    still writing it may hold a torn last line, passed over), the code of the runs they name, oldest first,
    and the cells those runs planned, in their plan's order (the newest run's first, as the sweep's report
    goes by its last run): both filled once every record was read, since a run line no record names (a run
    stopped before its first episode, a copied ``--reuse`` line whose records a kill cut off) made none of
    them."""
    commits: list[str] = []
    cells: list[dict[str, Any]] = []

    def records() -> Iterator[dict[str, Any]]:
        named: set[int | None] = set()
        for _, _, record in episode_log(path).scan(repair=False):
            named.add(run_number(record))
            yield record
        lines = [line for line in _run_lines(path, named) if isinstance(line, dict)]
        for line in lines:
            text = commit_text(line.get("code"))
            if text is not None and text not in commits:
                commits.append(text)
        for line in reversed(lines):  # workers append episodes as they finish, out of the plan's order
            planned = line.get("cells")
            if isinstance(planned, list):
                cells.extend(cell for cell in planned if isinstance(cell, dict))

    return records(), commits, cells


def _run_lines(path: Path, named: set[int | None]) -> list[Any]:
    """The run lines of ``path``'s sweep.json that a record ``named`` ran; every line where a record names
    no run (older sweeps); none where the file is missing or unreadable (the episodes are still compared; a
    damaged file said so)."""
    if not (path / SWEEP_FILE).exists():
        return []
    try:
        runs = read_sweep_file(path / SWEEP_FILE, hint="").get("runs", [])
    except (PipelineError, OSError) as exc:  # `sweep --report-only` refuses it: compare goes on, saying so
        print_note(f"note: {exc}; its episodes are compared without the code they ran")
        return []
    return runs_named(runs, named)


def simulate_records(path: Path) -> tuple[list[dict[str, Any]], list[str]]:
    """The episodes of a ``crowdmpc simulate --json`` file as a sweep's records and the code that ran them."""
    from pipelines.experiments.log import read_json_file

    document = read_json_file(path, "a simulate --json file")
    episodes = document.get("episodes") if isinstance(document, dict) else None
    if not (isinstance(episodes, list) and isinstance(document.get("summary"), dict)):
        raise PipelineError(f"{path}: not a `crowdmpc simulate --json` file (no summary and episodes)")
    crowd = _crowd_field(document.get("run"))
    records = [_record(episode, i, f"{path}: episode {i}", crowd=crowd) for i, episode in enumerate(episodes)]
    commit = commit_text(document.get("code"))
    return records, [] if commit is None else [commit]


def _record(
    episode: Any, index: int, where: str, key: str | None = None, crowd: dict[str, str] | None = None
) -> dict[str, Any]:
    """One simulated episode (simulate's JSON entry, or a recording's metrics with its config) as a sweep's
    record, checked as a sweep's log line is; ``crowd``: its run's ``_crowd_field``."""
    from pipelines.experiments.record_checks import check_record

    if not isinstance(episode, dict) or episode.get("seed") is None:
        raise PipelineError(f"{where} has no seed: an unseeded run's crowds pair with none")
    controller = str(episode.get("controller"))
    key = key or f"{controller}/{episode.get('scenario')}/{episode['seed']}"
    record = {**episode, "key": key, "cell": controller, "method": controller, "index": index, "wall_s": 0.0}
    record = {**_sensor_fields(episode.get("config")), **(crowd or {}), **record}
    check_record(record, where, "the file is damaged")  # no sweep's log: no episode runs again
    return record


def _sensor_fields(config: Any) -> dict[str, Any]:
    """The sweep record's ``sensor_range`` and ``sensor_tracks`` (pipelines/experiments/worker.py) of an
    episode whose config names its sensor: simulate's JSON and a recording hold it there alone, and without
    them a run behind the same sensor as a sweep's read as run with none."""
    sensing = config.get("sensing") if isinstance(config, dict) else None
    if not isinstance(sensing, dict):  # every human seen: null, as the sweep's records
        return {}
    radius = sensing.get("radius_m")
    return {"sensor_range": radius, "sensor_tracks": None if radius is None else sensing.get("report_tracks")}


def _crowd_field(run: Any) -> dict[str, str]:
    """The sweep record's ``crowd_sha256`` from a run's ``run`` (simulate's JSON, a recording's "run"
    metadata): the replayed file's sha256, which a sweep's record holds for a replayed crowd alone; none for
    ORCA's crowd (null) and for a run written before it was recorded, which is "(not recorded)", not null."""
    sha256 = run.get("crowd_sha256") if isinstance(run, dict) else None
    return {"crowd_sha256": sha256} if isinstance(sha256, str) else {}


def recording_records(
    path: Path, label: str, progress: bool | None = False
) -> tuple[list[dict[str, Any]], list[str]]:
    """The episodes recorded in ``path``, an .mcap file (or an unfinished .mcap.part, named) or a folder
    of them (as ``crowdmpc review`` finds them), as a sweep's records, and the code that recorded them
    (each commit once, in file order). A file that cannot be read, or whose episode did not finish (no
    metrics: its run was killed), is left out with a warning line, as are unfinished ``.mcap.part`` files:
    their episodes pair with none. A sweep's recordings are refused: it may have kept some episodes only
    (``--record failures``); its folder has them all."""
    from pipelines.logs.reader import find_recordings

    _refuse_sweep_recordings(path, label)
    if path.is_dir():
        files, unfinished = find_recordings(path)
        for part in unfinished:
            _warn(label, f"{part} is unfinished (still being written, or its run was killed): left out")
    else:
        files = [path]
    records: list[dict[str, Any]] = []
    commits: dict[str, None] = {}
    bar = progress_bar(
        files, show=progress, desc=f"reading {label}", unit="file", file=sys.stderr, leave=False
    )
    for file in bar:
        found = _read_episode(file, label, single=not path.is_dir())
        if found is None:
            continue
        episode, crowd, commit = found
        key = file.relative_to(path).as_posix() if path.is_dir() else file.name
        records.append(_record(episode, len(records), str(file), key, crowd))
        if commit is not None:
            commits.setdefault(commit)
    return records, list(commits)


def _read_episode(
    file: Path, label: str, single: bool
) -> tuple[dict[str, Any], dict[str, str], str | None] | None:
    """The recording's episode (its metrics message with the config it ran), its ``_crowd_field`` and its
    commit; None, warned, where a folder's file has none (``single``: the one file named is refused
    instead)."""
    from pipelines.logs.identity import null_none
    from pipelines.logs.reader import read_recording

    try:
        rec = read_recording(file, topics=[METRICS_TOPIC])
    except PipelineError as exc:
        if single:
            raise PipelineError(f"{label}: {exc}") from None
        _warn(label, f"{exc}; left out")
        return None
    messages = rec.data(METRICS_TOPIC)
    if not messages or not isinstance(messages[-1], dict):
        why = f"{file} holds no {METRICS_TOPIC} message " + (
            "(its episode did not finish: the run was killed)"
            if rec.truncated or not (rec.problems or rec.message_problems())
            else f"that reads ({(rec.problems + rec.message_problems())[0].removesuffix('; left out')}; "
            "`crowdmpc review --check` lists every problem)"
        )
        if single:
            raise PipelineError(f"{label}: {why}")
        _warn(label, f"{why}; left out")
        return None
    if rec.problems:  # the settings compared are its metadata, outside the chunks: a mismatch may be theirs
        more = f" (1 of {len(rec.problems)} problems)" if len(rec.problems) > 1 else ""
        _warn(label, f"{file}: {rec.problems[0]}{more}; `crowdmpc review --check` lists every problem")
    meta = rec.metadata.get("crowdmpc", {})
    # the diff's sha256, as a sweep's code shows it: without it two recordings of one dirty commit read as one
    # code ("null" where the tree was clean or git could not say; absent in older ones: "+dirty" alone)
    commit = commit_text(
        {
            "commit": meta.get("commit"),
            "dirty": meta.get("dirty") == "true",
            "diff_sha256": null_none(meta.get("diff_sha256")),
            "plugins": meta.get("plugins"),
            # what names code without a git commit (an installed wheel's recordings)
            **{key: null_none(meta.get(key)) for key, _ in CODE_VERSIONS},
        }
    )
    return {**messages[-1], "config": rec.config()}, _crowd_field(rec.run_meta()), commit


def _refuse_sweep_recordings(path: Path, label: str) -> None:
    """A sweep's DIR/mcap, DIR/mcap/CELL or a file in one: refused, naming the sweep's folder."""
    from pipelines.experiments.log import EPISODES_FILE, sweep_of_recordings

    sweep = sweep_of_recordings(path)
    if sweep is not None:
        raise PipelineError(
            f"{label}: {path} is a sweep's recordings, which may be some of its episodes only (sweep "
            f"--record failures); compare the sweep's folder {sweep}, whose {EPISODES_FILE} has all"
        )


def _warn(label: str, text: str) -> None:
    print_note(f"crowdmpc compare: warning: {label}: {text}")


def commit_text(code: Any) -> str | None:
    """A run's recorded code as "abc123def456+dirty" ("+dirty:0123abcd": its uncommitted changes' sha256,
    where recorded), then its plugins' files, "(plugin module:Class 0123456789ab)": runs of one commit and
    two versions of a user's net showed one code. Code without a git commit (an installed wheel, a `ray job
    submit` copy) is named by its versions, as table.md names it ("no git commit, crowdmpc 0.1.0, Python
    3.11.7, ..."): it read "code not recorded", as a run from before code was. None where nothing of the code
    was recorded."""
    if not isinstance(code, dict):
        return None
    commit = code.get("commit")
    if commit and commit != "null":
        text = str(commit)[:12] + dirty_text(code.get("dirty"), code.get("diff_sha256"))
    else:
        unnamed = no_commit_text(code)
        if unnamed is None:
            return None
        text = unnamed
    plugins = code.get("plugins")
    if isinstance(plugins, str):  # a recording's metadata holds it as JSON text
        try:
            plugins = json.loads(plugins)
        except (ValueError, RecursionError):  # json's parser recurses: text nested past the stack
            plugins = None
    if isinstance(plugins, dict) and plugins:
        shown = ", ".join(f"plugin {spec} {str(sha)[:12]}" for spec, sha in sorted(plugins.items()))
        text += f" ({shown})"
    return text
