"""The edges every benchmark script shares with ``crowdmpc``.

What a user types is checked when the command line is parsed (one line, exit 2), before any episode runs;
an error a user can cause later (a config file, a predictor's checkpoint) ends the script as it ends
``crowdmpc``: one line, exit 2, no traceback (``pipelines.cli.USER_ERRORS``); and a ``--json`` file is written
where it is asked for, its folder created, replacing only a JSON report and never one of the script's inputs,
as ``crowdmpc simulate --json`` does.

The benchmarks are scripts, not a package: each puts this folder on ``sys.path`` to import this module.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from crowdsim.scenarios import MAX_HUMANS, MAX_ROBOTS
from pipelines.cli import USER_ERRORS
from pipelines.commands import check_writable, first_repeat
from pipelines.commands.standard_output import hold_standard_descriptors, is_stdout, json_path, write_document
from pipelines.commands.standard_output import json_on_stdout as json_on_stdout  # the scripts' main()
from pipelines.config import ConfigError
from pipelines.errors import PipelineError
from pipelines.plain_json import plain
from predictors.registry import available


def count_in(what: str, low: int, high: int | None = None) -> Callable[[str], int]:
    """An argparse ``type``: an integer in ``low..high`` (``high`` None: at least ``low``), else the parser's
    one-line error naming ``what``."""
    wanted = f"an integer in {low}..{high}" if high is not None else f"an integer >= {low}"

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = None
        if value is None or value < low or (high is not None and value > high):
            raise argparse.ArgumentTypeError(f"{what} must be {wanted}, got {text!r}")
        return value

    return parse


robot_count = count_in("robots", 1, MAX_ROBOTS)
human_count = count_in("humans", 0, MAX_HUMANS)
# A predictor's own benchmark: with no human it has nothing to predict (an empty twin, no scalar to time).
predicted_humans = count_in("humans", 1, MAX_HUMANS)
# What a run repeats: none of them means nothing to measure (a division by zero or a nan table at the end).
episode_count = count_in("episodes", 1)
seed_number = count_in("seed", 0)  # numpy's generators refuse a negative seed


def predictor_name(text: str) -> str:
    """An argparse ``type``: a predictor ``crowdmpc`` knows (registered, or in the shipped or user zoo)."""
    names = available()
    if text not in names:
        raise argparse.ArgumentTypeError(f"unknown predictor {text!r}; choose from {', '.join(names)}")
    return text


def output_file(text: str) -> Path:
    """An argparse ``type``: a ``--json`` report's file, checked as ``crowdmpc simulate --json`` checks it: an
    existing folder, a place without write access, and an existing file that is not a JSON report (a CSV, a
    config, a recording: a mistyped name must not replace data) are refused now, not after the run; nothing
    is created. That it is none of the script's input files is checked once they are parsed
    (``check_not_input``). "-" is standard output (``standard_output.STDOUT``), as for ``crowdmpc``."""
    path = json_path(text)  # "-", and a missing folder's ".." taken away (pipelines/commands/output_paths)
    if is_stdout(path):
        return path
    if path.is_dir():
        raise argparse.ArgumentTypeError(f"{text} is a folder; expected the path of a file to write")
    try:
        check_writable(path, "file", json_only=True)
    except PipelineError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return path


def check_not_input(
    parser: argparse.ArgumentParser, option: str, path: Path | None, inputs: Iterable[str | Path | None]
) -> None:
    """After parsing: the output ``path`` of ``option`` is none of the files the script reads (``--config X
    --json X`` replaced the config it read, as ``crowdmpc`` refuses), else the parser's one-line error."""
    try:
        check_writable(path, option, inputs=[Path(p) for p in inputs if p is not None])
    except PipelineError as exc:
        parser.error(str(exc))


def check_input_files(parser: argparse.ArgumentParser, option: str, paths: Iterable[Path], what: str) -> None:
    """After parsing: each of ``option``'s ``paths`` an existing regular file, else the parser's one line
    naming the option, the path and ``what`` it should be (a missing run file was refused with Python's
    "[Errno 2] No such file or directory: 'nope.json'", which named neither)."""
    for path in paths:
        if not path.exists():
            parser.error(f"{option}: {path} does not exist; expected {what}")
        if not path.is_file():
            parser.error(f"{option}: {path} is not a file (a folder or a device); expected {what}")


def check_distinct(parser: argparse.ArgumentParser, option: str, values: Sequence[Any]) -> None:
    """After parsing: each of ``option``'s values once (``crowdmpc sweep --humans``'s rule), else the parser's
    one-line error. A repeat ran its rows twice and printed them twice, and where the report is keyed by the
    value, the JSON kept one of them (control_step.py --humans 1 1: 6 rows printed, 3 written)."""
    repeated = first_repeat(values)
    if repeated is not None:
        parser.error(f"{option} names {repeated} more than once")


def mpc_sets(texts: Sequence[str]) -> list[str]:
    """``--mpc KEY=VALUE`` items as the ``--set mpc.KEY=VALUE`` items the config loader parses; a malformed
    one is named in ``--mpc``'s own form."""
    for text in texts:
        key, equals, _ = text.partition("=")
        if not equals or not key.strip() or "." in key:
            raise ConfigError(f"--mpc {text!r}: expected KEY=VALUE of the [mpc] table, e.g. cost_scale=0.01")
    return [f"mpc.{text}" for text in texts]


def _path_as_text(value: Any) -> str:
    """The one type a benchmark's report holds that ``plain`` leaves as it is: a path (``vars(args)``)."""
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"{type(value).__name__} is not JSON serializable")


def json_text(payload: Any, indent: int = 2) -> str:
    """``payload`` as strict JSON: ``pipelines.plain_json.plain`` (NaN as null, numpy as Python), paths as
    text."""
    return json.dumps(plain(payload), indent=indent, allow_nan=False, default=_path_as_text)


def figure(value: float, spec: str) -> str:
    """``value`` formatted by ``spec`` for a printed table, or "-" in the same width where it was not
    measured (NaN)."""
    return format(value, spec) if math.isfinite(value) else "-".rjust(len(format(0.0, spec)))


def write_text(path: str | Path, text: str) -> None:
    """``text`` to ``path``, its folder created; to standard output for ``--json -`` (``output_file``)."""
    text = text if text.endswith("\n") else text + "\n"
    if is_stdout(path):
        write_document(text, "--json")
        return
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")


def write_json(path: str | Path, payload: Any, indent: int = 2) -> None:
    """``payload`` as strict JSON (``json_text``) to ``path``, its folder created."""
    write_text(path, json_text(payload, indent))


def episode_bar(episodes: int, desc: str) -> Iterator[int]:
    """``range(episodes)`` with a progress bar on stderr, as ``crowdmpc sweep`` shows one: a long benchmark
    prints its figures only at the end (stdout), and a bar says how far it is. It advances between episodes,
    outside every timed step, and goes when the loop ends."""
    from tqdm import tqdm

    return iter(tqdm(range(episodes), desc=desc, unit="ep", file=sys.stderr, leave=False))


@contextmanager
def private_cache(prefix: str) -> Iterator[Path]:
    """``$CROWDMPC_CACHE`` set to a new, empty folder for the run, removed after and the variable restored.

    A benchmark that compiles (jit) must neither fill the user's compile cache with the sizes it tries nor
    time loads of entries an earlier run left there: each run compiles from cold, as a fresh machine does,
    and the figures do not depend on what the cache held. The variable also roots the prepared datasets
    (``predictors.data.locate.cache_root``), which a run under this would prepare again: only the benchmarks
    that compile use it."""
    from mpc.cache_location import CACHE_ENV

    before = os.environ.get(CACHE_ENV)
    with tempfile.TemporaryDirectory(prefix=prefix) as folder:
        os.environ[CACHE_ENV] = folder
        try:
            yield Path(folder)
        finally:
            if before is None:
                del os.environ[CACHE_ENV]
            else:
                os.environ[CACHE_ENV] = before


def run_main(main: Callable[[], int | None]) -> int:
    """A script's ``main()`` (its command line from ``sys.argv``), with the errors a user can cause printed as
    one line and exit status 2, and a reader that left (``... | head``) ending it quietly, as ``crowdmpc``."""
    from pipelines.commands import quit_closed_stdout, stdout_reader_left

    hold_standard_descriptors()
    try:
        try:
            return int(main() or 0)
        finally:
            if sys.stdout is not None:  # None: started with standard output closed (`>&-`)
                sys.stdout.flush()
    except BrokenPipeError:
        if not stdout_reader_left():
            raise
        return quit_closed_stdout()
    except USER_ERRORS as exc:
        print(f"{Path(sys.argv[0]).name}: error: {exc}", file=sys.stderr)
        return 2
