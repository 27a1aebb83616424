"""pipelines.commands.calibrate_store on its own: when the blocks are stored, what a stopped or killed run
puts back, and the journal it leaves behind (none once it is done)."""

import os
import subprocess
import sys
from types import SimpleNamespace

import pytest

from pipelines.commands.calibrate_store import (
    _JOURNAL,
    _write_journal,
    plans_with_new_blocks,
    storing,
    take_back_killed,
)
from pipelines.errors import PipelineError
from pipelines.loop.margins import parse_margins
from predictors.calibration_store import calibrations_path, read_calibration_file, save_calibration
from tests.calibration_blocks import class_errors, constant_velocity_block


def _args(holdout_margins: str = "conformal:0.1") -> SimpleNamespace:
    """calibrate's arguments for constant_velocity's closed-loop calibration at alpha 0.1 with a held-out run
    planning with ``holdout_margins``."""
    return SimpleNamespace(
        dry_run=False,
        holdout=True,
        source="closed-loop",
        predictor="constant_velocity",
        alpha=[0.1],
        holdout_margins=holdout_margins,
    )


def _blocks():
    """A block with margins per motion class, so that it may replace the shipped one."""
    errors, motion = class_errors(4)
    return [constant_velocity_block(errors, classes=motion, shortfall=errors)]


def _journals(directory):
    return sorted(p.name for p in directory.glob(".calibrate-holdout.*"))


def test_a_held_out_run_planning_with_the_blocks_stores_them_first_and_leaves_no_journal(
    tmp_path, monkeypatch
):
    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path))
    path = calibrations_path()
    with storing(_blocks(), _args()) as blocks:
        assert [b.to_json() for b in read_calibration_file(path)] == [b.to_json() for b in blocks]
        assert [_JOURNAL.fullmatch(name)["pid"] for name in _journals(tmp_path)] == [str(os.getpid())]
    assert [b.to_json() for b in read_calibration_file(path)] == [b.to_json() for b in blocks]
    assert _journals(tmp_path) == []


def test_a_held_out_run_planning_with_the_blocks_makes_a_user_zoo_not_made_yet(tmp_path, monkeypatch):
    """A new user's first calibrate --holdout --holdout-margins conformal:A (A one of --alpha) ended in
    "No such file or directory: .../.calibrate-holdout.PID.json.tmp": the journal was written into the user
    zoo before storing the blocks made it."""
    zoo = tmp_path / "zoo"
    monkeypatch.setenv("CROWDMPC_ZOO", str(zoo))
    with storing(_blocks(), _args()) as blocks:
        assert [_JOURNAL.fullmatch(name)["pid"] for name in _journals(zoo)] == [str(os.getpid())]
    assert [b.to_json() for b in read_calibration_file(calibrations_path())] == [b.to_json() for b in blocks]
    assert _journals(zoo) == []


@pytest.mark.parametrize("dry_run", [False, True])
def test_the_blocks_record_the_code_that_measured_them(tmp_path, monkeypatch, dry_run):
    """Closed-loop margins are the MPC's episodes and a real block the predictor's errors, and a block said
    nothing of the code that made them, where every other output records it: the blocks stored, and those
    --json writes with --dry-run, carry ``details["code"]``, the rest of their details as they were."""
    from pipelines.plugins import code_with_plugins

    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path))
    made = _blocks()
    args = SimpleNamespace(**{**vars(_args()), "holdout": False, "dry_run": dry_run})
    with storing(made, args) as blocks:
        pass
    assert [b.details for b in blocks] == [{**b.details, "code": code_with_plugins()} for b in made]
    if dry_run:  # measured only: nothing stored
        assert not calibrations_path().exists()
    else:
        assert [b.details for b in read_calibration_file(calibrations_path())] == [b.details for b in blocks]


def test_a_stopped_held_out_run_with_no_earlier_file_leaves_no_file_and_no_journal(tmp_path, monkeypatch):
    """There was no calibrations file: taking the blocks back removes the file (an empty one is not "as it
    was"), and the journal goes with it."""
    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path))
    with pytest.raises(KeyboardInterrupt), storing(_blocks(), _args()):
        assert calibrations_path().exists()
        raise KeyboardInterrupt
    assert not calibrations_path().exists()
    assert _journals(tmp_path) == []


_TERMINATED_RUN = """
import os, signal
from types import SimpleNamespace
from pipelines.commands.calibrate_store import storing
from tests.calibration_blocks import class_errors, constant_velocity_block
errors, motion = class_errors(4)
blocks = [constant_velocity_block(errors, classes=motion, shortfall=errors)]
args = SimpleNamespace(dry_run=False, holdout=True, source="closed-loop", predictor="constant_velocity",
                       alpha=[0.1], holdout_margins="conformal:0.1")
try:
    with storing(blocks, args):
        os.kill(os.getpid(), signal.SIGTERM)  # `timeout` or a job scheduler, during the held-out episodes
except KeyboardInterrupt:
    print("interrupted")
"""


def test_a_terminated_held_out_run_puts_the_earlier_blocks_back(tmp_path):
    """SIGTERM (`timeout`, a job scheduler's stop) ran no finally: the blocks a calibrate stored for its
    held-out run stayed in force, so every simulate and sweep with --margins conformal:A planned with the
    unfinished run's margins until the next calibrate found its journal. It now ends the run as Ctrl-C does:
    the earlier blocks are put back (here: no file, as before) and no journal stays."""
    zoo = tmp_path / "zoo"
    env = {**os.environ, "CROWDMPC_ZOO": str(zoo)}
    done = subprocess.run([sys.executable, "-c", _TERMINATED_RUN], env=env, capture_output=True, text=True)
    assert done.stdout.splitlines()[-1:] == ["interrupted"], done.stderr[-2000:]
    assert not (zoo / "calibrations.json").exists() and _journals(zoo) == []


def test_a_block_without_class_margins_is_refused_before_anything_is_stored(tmp_path, monkeypatch):
    """The shipped constant_velocity block has margins per motion class: a block without them is not stored
    over it, and the run inside never starts."""
    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path))
    errors, motion = class_errors(4)
    few = constant_velocity_block(errors[motion != 0], classes=motion[motion != 0])
    ran = []
    for held in ("none", "conformal:0.1"):  # stored after the run, and before it
        with pytest.raises(PipelineError, match="has no margins per motion"), storing([few], _args(held)):
            ran.append(held)
    assert ran == [] and not calibrations_path().exists() and _journals(tmp_path) == []


@pytest.mark.parametrize("held", ["none", "conformal:0.1"], ids=["stored-after", "stored-before"])
def test_a_block_with_class_margins_stored_meanwhile_stays(tmp_path, monkeypatch, held):
    """Checked only at first: a full calibrate (margins per motion class) that stored its block during a
    short trial's held-out run had it replaced by the trial's block without them (two `calibrate --alpha
    0.002` at once, 60 and 20 episodes: the 20's block in force). Now checked again under the lock each block
    is stored under; refused before a held-out run that plans with it, nothing of the trial stays behind."""
    from pipelines.commands import calibrate_store

    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path / "zoo"))
    monkeypatch.setenv("CROWDMPC_CHECKPOINTS", str(tmp_path / "shipped"))  # no shipped block in force
    errors, motion = class_errors(4)
    few = constant_velocity_block(errors[motion != 0], classes=motion[motion != 0])
    (full,) = _blocks()
    write_journal = calibrate_store._write_journal

    def full_stored_first(*args):  # another calibrate stores its block just after this one's first check
        save_calibration(full)
        return write_journal(*args)

    monkeypatch.setattr(calibrate_store, "_write_journal", full_stored_first)
    ran = []
    with pytest.raises(PipelineError, match="has no margins per motion class"), storing([few], _args(held)):
        ran.append(held)
        if held == "none":
            save_calibration(full)  # another calibrate, during this one's held-out run
    assert ran == ([] if held != "none" else [held])
    assert [b.to_json() for b in read_calibration_file(calibrations_path())] == [full.to_json()]
    assert _journals(tmp_path / "zoo") == []


def test_the_journal_of_a_live_calibrate_is_not_taken_back(tmp_path, monkeypatch):
    """A journal whose calibrate still runs (here: a sleeping child; this process's own pid is a dead run's,
    since a run writes its journal only after taking those back) is that run's own business: its blocks stay
    in force and its journal stays."""
    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path))
    blocks = _blocks()
    path = save_calibration(blocks[0])
    live = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        journal, held = _write_journal(path, blocks, None)
        os.close(held)  # the pid alone says it runs
        journal.rename(journal.with_name(f".calibrate-holdout.{live.pid}.json"))
        take_back_killed()
        assert [b.to_json() for b in read_calibration_file(path)] == [b.to_json() for b in blocks]
        assert _journals(tmp_path) == [f".calibrate-holdout.{live.pid}.json"]
    finally:
        live.kill()
        live.wait()


def test_a_killed_calibrate_that_found_no_file_leaves_none(tmp_path, monkeypatch, capsys):
    """The journal records "no earlier file" (null), not "an empty file": taking the blocks back removes the
    calibrations file the killed run made."""
    from predictors import locking

    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path))
    blocks = _blocks()
    path = calibrations_path()
    os.close(_write_journal(path, blocks, None)[1])  # killed: its lock went with it
    save_calibration(blocks[0])
    monkeypatch.setattr(locking, "pid_alive", lambda pid: False)  # as if this process had been killed
    take_back_killed()
    assert not path.exists() and _journals(tmp_path) == []
    assert f"(pid {os.getpid()}) did not finish" in capsys.readouterr().out


def test_the_journal_of_a_calibrate_on_another_machine_is_not_taken_back(tmp_path, monkeypatch, capsys):
    """A calibrate on another node sharing the user zoo (a cluster's home directory) has a pid no process
    here has: a calibrate started here took back the blocks of its held-out run while that still ran ("a
    calibrate killed during its held-out run (pid N) did not finish"), and they were gone when it ended. The
    writer holds its journal's lock until its run ends; once it is released (the run killed), the blocks go.
    """
    from predictors import locking

    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path))
    blocks = _blocks()
    path = calibrations_path()
    journal, held = _write_journal(path, blocks, None)
    save_calibration(blocks[0])
    monkeypatch.setattr(locking, "pid_alive", lambda pid: False)  # its pid: no process here
    take_back_killed()
    assert [b.to_json() for b in read_calibration_file(path)] == [b.to_json() for b in blocks]
    assert _journals(tmp_path) == [journal.name] and capsys.readouterr().out == ""
    os.close(held)
    take_back_killed()
    assert not path.exists() and _journals(tmp_path) == []


def test_two_runs_of_one_pid_keep_two_journals(tmp_path, monkeypatch, capsys):
    """Two containers sharing a user zoo run every calibrate as PID 1: the journal named by the pid alone
    was the same file for both, and the run that ended first removed it; the other, killed in its held-out
    run, then left its blocks in force. Each run's journal is its own now."""
    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path))
    with storing(_blocks(), _args()):
        with storing(_blocks(), _args()):  # the same pid, as in two containers
            assert len(_journals(tmp_path)) == 2
        assert len(_journals(tmp_path)) == 1  # the first ended: its journal went, the second's stayed


def test_taking_back_in_a_zoo_not_made_yet_does_nothing(tmp_path, monkeypatch):
    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path / "no" / "zoo"))
    take_back_killed()
    assert not (tmp_path / "no").exists()


def test_held_out_margins_from_real_data_do_not_plan_with_the_closed_loop_blocks():
    """The blocks stored first are the ones the held-out run plans with: closed-loop blocks at one of
    --alpha. Margins calibrated on real data, or at another alpha, or no margins, plan with none of them."""
    args = _args()
    assert plans_with_new_blocks(args, parse_margins("conformal:0.1"))
    assert not plans_with_new_blocks(args, parse_margins("conformal:0.1:real"))
    assert not plans_with_new_blocks(args, parse_margins("conformal:0.2"))
    assert not plans_with_new_blocks(args, parse_margins("none"))
    assert not plans_with_new_blocks(
        SimpleNamespace(**{**vars(args), "holdout": False}), parse_margins("conformal:0.1")
    )


def test_a_run_of_several_alphas_stores_all_its_blocks_or_none(tmp_path, monkeypatch):
    """Each alpha's block was written on its own: a Ctrl-C, a full disk or a refusal between two writes left
    the first alphas' new blocks in force beside the last alphas' blocks of an earlier run."""
    import dataclasses

    from predictors import calibration_store

    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path))
    (block,) = _blocks()
    blocks = [dataclasses.replace(block, alpha=alpha) for alpha in (0.3, 0.2)]
    write = calibration_store.write_text_durably
    writes = []

    def full_at_the_second(path, text):
        writes.append(path)
        if len(writes) == 2:
            raise OSError(28, "No space left on device")
        write(path, text)

    monkeypatch.setattr(calibration_store, "write_text_durably", full_at_the_second)
    try:
        with storing(blocks, _args("none")):
            pass
    except OSError:
        pass
    stored = [b.alpha for b in read_calibration_file(calibrations_path())]
    assert sorted(stored) in ([], [0.2, 0.3])


def test_two_blocks_of_one_key_are_refused_before_the_write(tmp_path, monkeypatch):
    """save_calibrations wrote both, and every read of the file after it refused it (a block repeated):
    `zoo calibrations` and every run planning with calibrated margins failed until it was edited by hand."""
    import dataclasses

    from predictors.calibration_store import save_calibrations
    from predictors.errors import PredictorError

    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path))
    (block,) = _blocks()
    save_calibration(block)
    with pytest.raises(PredictorError, match=r"^blocks\[1\] repeats predictor 'constant_velocity'"):
        save_calibrations([block, dataclasses.replace(block, alpha=0.1 + 5e-13)])
    assert read_calibration_file(calibrations_path()) == [block]


@pytest.mark.parametrize(
    ("content", "reason"),
    [
        ("[" * 100_000 + "]" * 100_000, "maximum recursion depth exceeded"),
        ('{"stored": [], "earlier": 1' + "0" * 5000 + "}", "Exceeds the limit (4300 digits)"),
    ],
    ids=["nested", "long-integer"],
)
def test_a_damaged_journal_is_refused_in_one_line(tmp_path, monkeypatch, content, reason):
    """The journal's reader caught json's ValueError but not its RecursionError: a journal nested past the
    stack ended `crowdmpc simulate --margins conformal:0.1` (and every run taking killed blocks back) in a
    traceback, where other damage is one line naming the journal."""
    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path))
    journal = tmp_path / ".calibrate-holdout.999999.json"  # a pid no process has here
    journal.write_text(content)
    monkeypatch.setattr("predictors.locking.pid_alive", lambda pid: False)
    with pytest.raises(PipelineError) as refused:
        take_back_killed()
    said = str(refused.value)
    assert said.startswith(
        f"{journal}: a killed calibrate's record of the blocks to take back is unreadable ("
    )
    assert reason in said and "\n" not in said and journal.read_text() == content
