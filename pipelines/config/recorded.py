"""A sweep's recorded config, back as a ``RunConfig``: ``crowdmpc config show --from-sweep DIR`` prints the
TOML that reruns what a sweep directory holds (each run line of ``sweep.json`` keeps the effective config it
ran with, ``RunConfig.effective``, and the code it ran: ``pipelines.version.code_identity``).

The recorded values go through the same resolver as a config file's (unknown sections and keys, types and
bounds refused, naming ``sweep.json``), so what comes out loads back to the same run.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pipelines.config.resolve import ConfigError, Entry, RunConfig, Source, _check_key, resolve
from pipelines.config.schema import SECTION_BY_NAME


def recorded_runs(directory: Path) -> tuple[Path, list[dict[str, Any]]]:
    """``(sweep.json's path, its run lines)``; ConfigError when ``directory`` holds no sweep."""
    from pipelines.experiments.log import SWEEP_FILE, read_sweep_file

    path = Path(directory) / SWEEP_FILE
    if not path.is_file():
        raise ConfigError(f"--from-sweep {directory}: no {SWEEP_FILE} (not a sweep directory)")
    runs = [r for r in read_sweep_file(path).get("runs", []) if isinstance(r, dict)]
    if not runs:
        raise ConfigError(f"--from-sweep {directory}: {path} records no run")
    return path, runs


def recorded_config(path: Path, run: dict[str, Any], index: int) -> RunConfig:
    """The config run ``index`` (1-based) of ``path`` recorded, resolved as a config file would be."""
    where = f"{path} (run {index})"
    values = run.get("config")
    if not isinstance(values, dict):
        raise ConfigError(
            f"{where} records no config (a sweep from before configs were kept); rerun it from its options"
        )
    source = Source("file", where)
    entries: list[Entry] = []
    for name, section in values.items():
        if name == "config_file":  # where the values came from, not a value
            continue
        if name not in SECTION_BY_NAME or not isinstance(section, dict):
            raise ConfigError(f"{where}: unknown config section {name!r}; the file is damaged")
        for key, value in section.items():
            _check_key(source.prefix(name, key), SECTION_BY_NAME[name], key)
            if value is not None:  # null: unset, as a file leaves it out
                entries.append(Entry(name, key, value, source))
    return resolve(entries, where)


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
    )


def _plain(value: Any) -> str:
    """A recorded value inside a comment: one short line (a line break in it would end the comment, and what
    follows would be read as TOML)."""
    return " ".join(str(value).split())[:80]
