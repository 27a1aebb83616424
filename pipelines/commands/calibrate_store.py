"""Storing ``crowdmpc calibrate``'s blocks in the user zoo's calibrations file: after the held-out run, so
that an interrupted or failed command leaves the user's calibrations as they were, or before it when its
episodes plan with them, the earlier blocks put back if the run stops (by the next calibrate when a kill left
no chance: ``take_back_killed``); never a block without margins per motion class over one that has them.
The notes on what the blocks stored will be: fitted on evaluation seeds, made otherwise than those they
replace."""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import fcntl
import json
import os
import re
import secrets
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Final

from pipelines.commands import comma_items
from pipelines.errors import PipelineError, print_note
from predictors.durable import replace_durably
from predictors.errors import PredictorError
from predictors.locking import pid_alive, unless_held

if TYPE_CHECKING:
    from pipelines.loop.margins import MarginSpec
    from predictors.calibration import Calibration

# what a calibrate storing blocks before its held-out run would take back, beside the calibrations file:
# .calibrate-holdout.PID-RANDOM.json (.PID.json before the RANDOM). The pid alone was no run's own name: two
# containers sharing a user zoo run every calibrate as PID 1, and the one that ended first removed the
# journal of the other (which had written over its own), whose blocks then stayed in force once it was killed.
_JOURNAL: Final = re.compile(
    r"\.calibrate-holdout\.(?P<pid>[0-9]+)(?:-[0-9a-f]{8})?\.json(?P<unfinished>\.tmp)?"
)


def alphas_arg(text: str) -> tuple[float, ...]:
    """``--alpha``'s argparse type: distinct alphas in (0, 1), each at least ``MIN_ALPHA``: one block each."""
    try:
        values = tuple(float(v) for v in comma_items(text))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--alpha takes numbers like 0.1,0.05, got {text!r}") from None
    if not values or not all(0.0 < a < 1.0 for a in values):
        raise argparse.ArgumentTypeError(f"--alpha needs numbers in (0, 1), got {text!r}")
    from predictors.calibration import same_alpha
    from predictors.conformal import MIN_ALPHA

    if min(values) < MIN_ALPHA:  # its margin would need more than 10^12 samples (predictors.conformal)
        raise argparse.ArgumentTypeError(f"--alpha needs numbers of at least {MIN_ALPHA:g}, got {text!r}")
    # one block per alpha: a repeat (within the calibration key's tolerance) would be stored once
    for i, a in enumerate(values):
        same = [b for b in values[:i] if same_alpha(a, b)]
        if same:
            twice = f"{a!r} twice" if same[0] == a else f"{same[0]!r} and {a!r}, one calibration,"
            raise argparse.ArgumentTypeError(f"--alpha names {twice} in {text!r}; give each alpha once")
    return values


def plans_with_new_blocks(args: argparse.Namespace, holdout_margins: MarginSpec) -> bool:
    """Whether the held-out episodes plan with margins of a block this run stores (--holdout-margins
    conformal:A with A one of --alpha), which must then be stored before them; PipelineError when --dry-run
    stores nothing."""
    from pipelines.loop.margins import CALIBRATED_MODES
    from predictors.calibration import same_alpha

    names = (
        args.holdout
        and args.source == "closed-loop"
        and holdout_margins.mode in CALIBRATED_MODES
        and holdout_margins.source == "closed-loop"
        and any(same_alpha(holdout_margins.alpha, a) for a in args.alpha)
    )
    if names and args.dry_run:  # they planned with the block stored before, its coverage printed as the new's
        raise PipelineError(
            f"--holdout-margins {args.holdout_margins} plans the held-out episodes with this run's block, "
            "which --dry-run does not store: they would plan with the block stored before (or find none); "
            "drop --dry-run (with CROWDMPC_ZOO=DIR, a scratch copy of your user zoo, to keep yours as it "
            "is), or hold out with --holdout-margins none or fixed:M1,...,MH"
        )
    return bool(names)


def evaluation_seeds_note(seed: int, episodes: int) -> str | None:
    """A line for calibration episodes on seeds that simulate and sweep evaluate on from their default --seed
    (simulate's episode i: seed + i, at most MAX_SIMULATE_EPISODES; a sweep cell's: seed + i // 2), None
    otherwise: the blocks stored would cover those very episodes, where the default, CALIBRATION_SEED on,
    keeps the two apart. Not refused: it may be meant."""
    from pipelines.config.settings import MAX_SIMULATE_EPISODES, SimulateSettings, SweepSettings
    from pipelines.experiments.calibrate import CALIBRATION_SEED
    from pipelines.experiments.sweep_config import MAX_EPISODES_PER_CELL

    first = min(SimulateSettings.seed, SweepSettings.seed)
    last = first + max(MAX_SIMULATE_EPISODES, (MAX_EPISODES_PER_CELL + 1) // 2) - 1
    shared = (max(seed, first), min(seed + episodes - 1, last))
    if shared[0] > shared[1]:
        return None
    return (
        f"note: calibration seeds {_seeds(seed, seed + episodes - 1)} overlap the evaluation seeds "
        f"{_seeds(first, last)} (simulate and sweep from their default --seed {first}) at {_seeds(*shared)}: "
        "the margins would be fitted on episodes they are later evaluated on (the default --seed "
        f"{CALIBRATION_SEED} keeps them apart)"
    )


def trained_on_notes(predictor: str, calibrated: list[Path], held_out: list[Path]) -> list[str]:
    """A line for each real scene file, of those ``calibrated`` on and those ``held_out`` for coverage, that
    ``predictor`` was trained on (its zoo entry's training files, by sha256): a model's errors on the data it
    was fitted to are smaller than elsewhere, so margins calibrated there cover less than 1 - alpha on other
    people, and coverage measured there is more than they have. Not refused: it may be meant. The validation
    files, which chose the best epoch (the shipped models': the calibration's), are not trained on."""
    from predictors.registry import PREDICTORS
    from predictors.zoo import locate

    located = None if predictor in PREDICTORS else locate(predictor)
    if located is None:  # constant velocity: nothing learned
        return []
    calibrated_on = "the margins are calibrated", "they cover less than 1 - alpha of people it has not seen"
    measured_on = "held-out coverage is measured", "it overstates what they cover of people it has not seen"
    notes = []
    for paths, (what, so) in ((calibrated, calibrated_on), (held_out, measured_on)):
        for path, split, name in located.entry.seen_in_training(paths):
            if split == "train":
                notes.append(
                    f"note: {what} on {path}, which holds data {predictor} was trained on (its training "
                    f"file {name}): {so}"
                )
    return notes


def _seeds(first: int, last: int) -> str:
    return str(first) if first == last else f"{first}..{last}"


@contextlib.contextmanager
def storing(blocks: list, args: argparse.Namespace) -> Iterator[list]:
    """Store ``blocks`` (not with --dry-run) once the held-out run inside has finished: an interrupted or
    failed command leaves the user's calibrations as they were. When the held-out episodes plan with these
    blocks they are stored first, and the earlier blocks of their keys are put back if the run stops (blocks
    another calibrate stored meanwhile stay). Yields the blocks as they are stored: with the code that
    measured them (``details["code"]``), as every other output records it."""
    from pipelines.loop.margins import parse_margins
    from pipelines.plugins import code_with_plugins
    from predictors.calibration_store import calibrations_path, read_calibration_file

    # here, before any journal: a take-back finds the blocks as they were stored (closed-loop margins are the
    # MPC's episodes, a real block the predictor's errors; both change with the code)
    blocks = [dataclasses.replace(b, details={**b.details, "code": code_with_plugins()}) for b in blocks]
    if args.dry_run:
        yield blocks
        return
    _check_keeps_class_margins(blocks, args)  # now, not after the held-out run; and again as they are stored
    if not plans_with_new_blocks(args, parse_margins(args.holdout_margins)):
        yield blocks
        _store(blocks, args)
        return
    from pipelines.loop.interrupt import terminate_as_interrupt

    path = calibrations_path()
    before = read_calibration_file(path) if path.exists() else None
    # A SIGTERM (`timeout`, a job scheduler) or SIGHUP ran no finally: the blocks stayed in force for every
    # simulate and sweep until the next calibrate found the journal. As Ctrl-C, they are put back now.
    with terminate_as_interrupt():
        yield from _stored_for_the_run(blocks, args, path, before)


def _stored_for_the_run(
    blocks: list, args: argparse.Namespace, path: Path, before: list | None
) -> Iterator[list]:
    """``storing``'s case of a held-out run that plans with ``blocks``: stored before it, journalled, and
    the earlier blocks ``before`` put back if it stops."""
    journal, held = _write_journal(path, blocks, before)
    try:
        try:
            _store(blocks, args)
            yield blocks
        except BaseException:  # Ctrl-C too, and a refusal of a block (another calibrate stored one since)
            _put_back(blocks, before)
            raise
        finally:
            journal.unlink(missing_ok=True)
    finally:
        os.close(held)  # the journal's lock, once it is gone


def take_back_killed() -> None:
    """Take back the blocks of each calibrate killed during a held-out run that planned with them (kill -9,
    a crash: no chance to put them back itself), as its Ctrl-C would have: from the journal it left."""
    from predictors.calibration_store import calibrations_path
    from predictors.zoo import is_shipped, user_zoo_dir

    # $CROWDMPC_ZOO at the shipped zoo, which is read as the one zoo: no calibrate wrote a journal there, and
    # calibrations_path() refuses it as a zoo to write, which failed `zoo calibrations` and every run planning
    # with calibrated margins
    if is_shipped(user_zoo_dir()):
        return
    path = calibrations_path()
    if not path.parent.is_dir():
        return
    for journal in sorted(path.parent.iterdir()):
        match = _JOURNAL.fullmatch(journal.name)
        # this run has written no journal yet: one under its own PID is a killed run's whose PID it got (every
        # run in a fresh container is PID 1), and it would write its own journal over that one
        if match is None or (int(match["pid"]) != os.getpid() and pid_alive(int(match["pid"]))):
            continue
        # the writer holds the journal's lock until its run ends, on whatever machine: a pid names a process
        # of one machine only; a journal another calibrate took back meanwhile is gone (not free)
        with unless_held(journal, gone=False) as free:
            if free:
                _take_back(journal, match, path)


def take_back_before_planning(margins: Iterable[MarginSpec]) -> None:
    """``take_back_killed`` before a run plans with any of ``margins`` that a calibration gives: a calibrate
    killed while its held-out episodes planned with its new blocks left them in force, and simulate and
    sweep planned with them, unsaid, until the next calibrate took them back."""
    from pipelines.loop.margins import CALIBRATED_MODES

    if any(spec.mode in CALIBRATED_MODES for spec in margins):
        take_back_killed()


def _take_back(journal: Path, match: re.Match[str], path: Path) -> None:
    """Put back what the killed calibrate of ``journal`` stored in the calibrations file ``path``."""
    from predictors.calibration import Calibration

    if match["unfinished"]:  # killed while writing it, before any block was stored
        journal.unlink(missing_ok=True)
        return
    try:
        document = json.loads(journal.read_text(encoding="utf-8"))
        stored = [Calibration.from_json(b, journal) for b in document["stored"]]
        earlier = document["earlier"]
        if earlier is not None:
            earlier = [Calibration.from_json(b, journal) for b in earlier]
    # RecursionError: json's parser recurses, and a journal edited to nest deeper than the stack is unreadable
    except (OSError, ValueError, KeyError, TypeError, RecursionError, PredictorError) as exc:
        raise PipelineError(
            f"{journal}: a killed calibrate's record of the blocks to take back is unreadable ({exc}); "
            f"check {path} and remove {journal.name}"
        ) from None
    _put_back(stored, earlier, f"a calibrate killed during its held-out run (pid {match['pid']})")
    journal.unlink(missing_ok=True)


def _write_journal(path: Path, blocks: list, before: list | None) -> tuple[Path, int]:
    """The record ``take_back_killed`` reads, durable before any block is stored, and a descriptor holding
    its lock (``predictors.locking.unless_held``), taken before it has its name: the caller closes it once
    its run ends."""
    journal = path.with_name(f".calibrate-holdout.{os.getpid()}-{secrets.token_hex(4)}.json")
    document = {
        "stored": [b.to_json() for b in blocks],
        "earlier": None if before is None else [b.to_json() for b in before],
    }
    tmp = journal.with_name(journal.name + ".tmp")
    path.parent.mkdir(parents=True, exist_ok=True)  # a user zoo not made yet: storing the blocks makes it
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_NOFOLLOW, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
        except OSError as exc:  # ENOLCK (an NFS mount without its lock daemon), EOPNOTSUPP
            tmp.unlink(missing_ok=True)
            raise PipelineError(
                f"{tmp}: cannot lock calibrate's journal ({exc.strerror}: its file system does not lock "
                "files; an NFS mount without its lock daemon?); set $CROWDMPC_ZOO to a folder on one that "
                "does"
            ) from None
        with open(fd, "w", encoding="utf-8", closefd=False) as f:
            f.write(json.dumps(document, allow_nan=False))
        replace_durably(tmp, journal)
    except BaseException:
        os.close(fd)
        raise
    return journal, fd


def _store(blocks: list, args: argparse.Namespace) -> None:
    """Store ``blocks``, all in one write, refused (``_check_keeps_class_margins``) under the lock it is
    written under: a calibrate running meanwhile (another job on the same user zoo) may have stored a block
    with margins per motion class since this one checked, before its held-out run, and a short trial
    replaced it."""
    from predictors.calibration_store import save_calibrations, stored_calibrations

    in_force = stored_calibrations()
    notes = [_replaced_note(block, in_force) for block in blocks]
    path = save_calibrations(blocks, check=lambda: _check_keeps_class_margins(blocks, args))
    for note in filter(None, notes):  # once they are stored: blocks refused replace nothing
        print_note(note)
    print(f"wrote {len(blocks)} block(s) to {path}")


def _replaced_note(block: Calibration, in_force: list[tuple[Path, Calibration]]) -> str | None:
    """A line for a block that takes the place of one made with other settings (another controller, other
    seeds or episodes: ``made_with``; another horizon), None otherwise: runs planning with that alpha then
    plan with margins of other episodes, and one calibration silently replaced another (a trial with
    --controller dmpc the CMPC block that --margins conformal:ALPHA meant). Settings the old block does not
    record are passed over."""
    from predictors.calibration_store import made_with
    from predictors.conformal import alpha_text

    replaced = [(path, old) for path, old in in_force if old.same_key(block)]
    if not replaced:
        return None
    path, old = replaced[0]
    # the horizon too: a real block at --horizon 3 replaced the one at 4 in silence, and every run at
    # Table I's horizon was then refused
    before = made_with(old) | {"horizon": str(len(old.quantiles))}
    now = made_with(block) | {"horizon": str(len(block.quantiles))}
    differ = [key for key in before if before[key] != now.get(key)]
    if not differ:
        return None
    view = f"alpha {alpha_text(block.alpha)}"
    view += "" if block.sensor_range is None else f" behind a {block.sensor_range:g} m sensor"
    view += "" if block.sensor_tracks else " without track lengths"
    return (
        f"note: this replaces the {block.source} block of {block.predictor} at {view} in force from {path}, "
        "made with "
        + " ".join(f"--{key} {before[key]}" for key in differ)
        + "; this one is made with "
        + " ".join(f"--{key} {now.get(key, '(not recorded)')}" for key in differ)
    )


def _put_back(blocks: list, before: list | None, who: str = "the held-out run") -> None:
    """The calibrations file without ``blocks``: the blocks of their keys in ``before`` (the file's blocks
    before the run ``who`` names; None: there was no file) back in their place."""
    from predictors.calibration_store import undo_calibrations

    try:
        path = undo_calibrations(blocks, before)
    except (OSError, PredictorError) as exc:
        raise PipelineError(
            f"{who} stopped and the calibrations it stored could not be taken back ({exc})"
        ) from None
    print(f"{who} did not finish: its blocks are taken out of {path}, the earlier ones put back")


def _check_keeps_class_margins(blocks: list, args: argparse.Namespace) -> None:
    """Refuse to store a block without margins per motion class where runs with its view of the humans plan
    with one that has them (the shipped block, the user's earlier one, or, behind a sensor not calibrated for
    yet, the one made with every human in view): a short trial run would otherwise make conformal-motion and
    conformal-shortfall, which docs/examples/safe_crossing.toml plans with, refuse that predictor."""
    from pipelines.loop.margins import class_tables
    from predictors.calibration_store import stored_calibrations, view_distance

    in_force = stored_calibrations()
    losing: list[Calibration] = []
    having: set[Path] = set()  # the files of the blocks in force that have them
    for block in blocks:
        new = class_tables(block)
        # a block of other weights than the new one's is refused by every run (find_calibration): no run
        # plans with its margins per class, and a retrained model could not replace it without them
        planned = [
            (path, old)
            for path, old in in_force
            if old.matches(block.predictor, block.source, block.alpha)
            and old.predictor_sha256 == block.predictor_sha256
        ]
        if not planned:
            continue
        path, old = min(planned, key=lambda found: view_distance(found[1].key()[3:], block.key()[3:]))
        if any(new[mode] is None and had is not None for mode, had in class_tables(old).items()):
            losing.append(block)
            having.add(path)
    if losing:
        raise PipelineError(_losing_class_margins(losing, sorted(having), args))


def _losing_class_margins(losing: list[Calibration], having: list[Path], args: argparse.Namespace) -> str:
    """Why ``losing`` (blocks without margins per motion class where runs plan with blocks of ``having``'s
    files that have them) are not stored, and the command that makes them: the same with more episodes."""
    from pipelines.experiments.calibrate import ClosedLoopPlan
    from predictors.calibration_store import calibrate_command
    from predictors.conformal import alpha_text

    alphas = [b.alpha for b in losing]
    one = len(losing) == 1
    had = losing[0].details.get("episodes")
    more = max(ClosedLoopPlan.episodes, 2 * had) if isinstance(had, int) else ClosedLoopPlan.episodes
    in_episodes = f" in {had} episodes" if isinstance(had, int) else ""
    return (
        f"not stored: the new {args.source} block{'' if one else 's'} of {args.predictor} at alpha "
        f"{', '.join(alpha_text(a) for a in alphas)} {'has' if one else 'have'} no margins per motion class "
        f"(a class had too few samples{in_episodes}), and runs plan now with "
        f"{'a block that has' if one else 'blocks that have'} them (in {', '.join(map(str, having))}); make "
        f"{'it' if one else 'them'} with more episodes: {calibrate_command(losing[0], alphas, episodes=more)}"
        ", or measure without storing with --dry-run"
    )
