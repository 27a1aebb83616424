"""``crowdmpc data synth``: synthetic ORCA scenes written under a temporary name, with their provenance
beside them, one run into an --out at a time."""

from __future__ import annotations

import argparse
import os
import re
from pathlib import Path
from typing import Final

from crowdsim.profiles import make_env_config
from pipelines.commands import check_writable, replace_file
from pipelines.commands.standard_output import shown
from pipelines.config.settings import check_last_seed
from pipelines.errors import PipelineError, writes_named
from predictors.durable import replace_durably

PART_SUFFIX: Final[str] = ".part"  # a file's name until it is complete
# How much longer than --out's name data synth's longest temporary name is: write_ndjson's own temporary
# ".STAGED.PID.tmp" of the staged ".NAME.synth-PID.part" (a PID has at most 7 digits)
SYNTH_NAME_ROOM: Final[int] = len("..") + len(f".synth-{9999999}{PART_SUFFIX}") + len(f".{9999999}.tmp")


def provenance_path(out: Path) -> Path:
    """Where ``data synth`` records how it made ``out``: NAME.synth.json beside it (no data glob takes it)."""
    return out.with_suffix(".synth.json")


def run_synth(args: argparse.Namespace) -> int:
    check_last_seed(args.seed, args.episodes - 1, f"{args.episodes} episodes", "--seed")
    check_writable(args.out, "--out", room=SYNTH_NAME_ROOM, renamed=True)
    provenance = provenance_path(args.out)
    check_writable(provenance, "--out's provenance file", renamed=True)
    try:
        from pipelines.experiments.synth import synthesize
    except ModuleNotFoundError as exc:
        if exc.name != "pipelines.experiments.synth":
            raise
        raise PipelineError(
            "synthetic data needs pipelines/experiments/synth.py (the crowd simulator): not installed"
        ) from None
    # What --out holds is judged under the lock: one checked before another run's data was there replaced
    # it without --replace.
    with _one_synth_at_a_time(args.out):
        _check_provenance_is_outs(args, provenance)
        for path in (args.out, provenance):
            if path.exists() and path.stat().st_size > 0 and not args.replace and not _rerun_of(args, path):
                # a mistyped --out replaced a training file; the same command regenerates the same bytes
                raise PipelineError(f"--out {path} exists; add --replace to replace it, or name another file")
        summary = _synthesize_into(args, provenance, synthesize)
    for key, value in summary.items():
        print(f"{key}: {value}")
    print(f"provenance: {provenance}")
    return 0


def _synthesize_into(args: argparse.Namespace, provenance: Path, synthesize) -> dict:
    """Run ``synthesize`` for --out and put its data and ``provenance`` in place; its summary."""
    # The data is made under a temporary name (no data glob takes it) and renamed into place after its
    # provenance is: data at --out always has its provenance beside it, and the provenance is its own.
    staged = args.out.with_name(f".{args.out.name}.synth-{os.getpid()}{PART_SUFFIX}")
    _remove_dead_staged(args.out)
    with writes_named(args.out):  # a full disk's error names --out (a write's names no file)
        try:
            summary = synthesize(
                staged,
                args.episodes,
                args.humans,
                args.seed,
                scenario=args.scenario,
                with_robots=args.with_robots,
                env_config=make_env_config(args.profile),
                progress=False if args.no_progress else None,
            )
            if "path" in summary:
                summary["path"] = shown(args.out)  # "./-", not "-", which reads as standard output
            provenance.unlink(missing_ok=True)  # the old data goes without provenance, never beside the new
            args.out.unlink(missing_ok=True)
            _write_provenance(args, summary, provenance, staged)
            replace_durably(staged, args.out)
        finally:
            staged.unlink(missing_ok=True)
    return summary


def _synth_lock_path(out: Path) -> Path:
    """The lock of the synths into ``out``: a hidden ``.NAME.synth.lock`` beside it (in its folder as
    resolved, so that two spellings of one folder share it)."""
    return out.parent.resolve() / f".{out.name}.synth.lock"


def _one_synth_at_a_time(out: Path):
    """Hold ``out``'s lock while a synth writes it; a second synth into it is refused, as a second train or
    sweep into one folder is: two finishing together paired one's data with the other's provenance (each
    renamed its data into place after writing its provenance), and one waiting for the other would find
    its data there and replace it, or be refused, after a wait of up to an hour. A run that fails leaves no
    folder it made, nor a lock it made: a sweep --out refused the folder it was left in."""
    from predictors.locking import locked_undone_on_failure

    def refuse() -> None:
        raise PipelineError(
            f"another crowdmpc data synth is writing --out {out}; wait for it or name another file"
        )

    return locked_undone_on_failure(_synth_lock_path(out), f"lock --out {out}", waiting=refuse)


def _remove_dead_staged(out: Path) -> None:
    """The staged data beside ``out`` of a `data synth` killed before its rename (its process is gone), and
    the writer's own temporary of it (``.STAGED.PID.tmp``, ``write_ndjson``) when it was killed while writing:
    that one was left there for good."""
    from predictors.locking import pid_alive

    staged = rf"\.{re.escape(out.name)}\.synth-(\d+){re.escape(PART_SUFFIX)}"
    patterns = (re.compile(staged), re.compile(rf"\.{staged}\.\1\.tmp"))
    for entry in out.parent.iterdir() if out.parent.is_dir() else ():
        match = next((m for m in (p.fullmatch(entry.name) for p in patterns) if m), None)
        if match and not entry.is_symlink() and entry.is_file() and not pid_alive(int(match[1])):
            entry.unlink(missing_ok=True)


def _provenance(path: Path) -> dict | None:
    """The provenance document at ``path``; None when it is none (missing, unreadable, not JSON).
    PipelineError naming it for a key given twice: json kept the last without a word, so whose data it
    records ("data") could not be told; refused, as every JSON file a user may edit is (``unique_keys``)."""
    import json

    from predictors.errors import DuplicateKey, unique_keys

    try:
        document = json.loads(path.read_text(encoding="utf-8"), object_pairs_hook=unique_keys)
    except DuplicateKey as exc:  # before ValueError, which it is
        raise PipelineError(f"{path}: {exc}") from None
    # ValueError: UnicodeDecodeError, JSONDecodeError and an integer past Python's 4300 digits, which json
    # raises as a plain ValueError; RecursionError: nesting past the stack (json's parser recurses)
    except (OSError, ValueError, RecursionError):
        return None
    return document if isinstance(document, dict) else None


def _rerun_of(args: argparse.Namespace, path: Path) -> bool:
    """Whether ``path`` is the provenance, without its data, of this very command (one stopped between the
    two renames): the rerun writes the same, so it need not be told to --replace it."""
    if path == args.out or args.out.exists():
        return False
    document = _provenance(path)
    return (
        document is not None
        and document.get("data") == args.out.name
        and document.get("options") == _synth_options(args)
    )


def _check_provenance_is_outs(args: argparse.Namespace, provenance: Path) -> None:
    """``--out x.json``'s provenance is named as ``x.ndjson``'s (NAME.synth.json): the one of another data
    file there is refused, --replace or not (it went, silently, and x.ndjson was left without its own)."""
    document = _provenance(provenance) if provenance.is_file() else None
    data = document.get("data") if document is not None else None
    if isinstance(data, str) and data != args.out.name and (args.out.parent / data).exists():
        raise PipelineError(
            f"--out {args.out}: its provenance file {provenance} is that of {args.out.parent / data}, beside "
            "it; name the output otherwise (e.g. NAME.ndjson)"
        )


def _synth_options(args: argparse.Namespace) -> dict:
    options = {
        "episodes": args.episodes,
        "humans": args.humans,
        "seed": args.seed,
        "scenario": args.scenario,
        "with_robots": args.with_robots,
    }
    # the default profile is left out: the options of a set made before --profile stay the same command's
    return options if args.profile == "paper" else {**options, "profile": args.profile}


def _write_provenance(args: argparse.Namespace, summary: dict, path: Path, data: Path) -> None:
    """The options, the data's sha256 and the code that made it: training records the data's hashes only,
    and a synthetic set is rebuilt (bit for bit) from these alone."""
    import json

    from pipelines.plain_json import plain
    from pipelines.version import code_identity
    from predictors.hashing import sha256_file

    document = {
        "format": "crowdmpc-synth",
        "version": 1,
        "data": args.out.name,
        "sha256": sha256_file(data),
        "options": _synth_options(args),
        "summary": summary,
        "code": code_identity(),
    }
    # a temporary name of its own (replace_file): a fixed one was shared by two synths into the same --out,
    # each removing or renaming the other's, and one a killed run left there (a link) was written through
    text = json.dumps(plain(document), indent=2) + "\n"
    replace_file(path, lambda name: Path(name).write_text(text, encoding="utf-8"))
