"""``crowdmpc cache info|clear`` on a private $CROWDMPC_CACHE."""

import contextlib
import json

import casadi as ca
import pytest

from mpc import cache_location, compile_cache
from mpc.cache_entries import locked
from pipelines.cli import main
from tests.waits import within


@pytest.fixture
def folder(tmp_path, monkeypatch):
    monkeypatch.setenv(compile_cache.CACHE_ENV, str(tmp_path / "cache"))
    return tmp_path / "cache" / "compiled"


def test_info_on_a_cache_not_created_yet(folder, capsys):
    assert main(["cache", "info"]) == 0
    out = capsys.readouterr().out
    assert f"directory: {folder} (not created yet)" in out
    assert "entries:   0 (0 files, 0 B)" in out
    assert f"casadi:    {ca.__version__}" in out


def test_info_counts_entries_and_clear_removes_only_ours(folder, capsys):
    folder.mkdir(parents=True)
    key = "0123456789abcdef" * 4
    (folder / f"{key}.casadi").write_bytes(b"s" * 1000)
    (folder / f"{key}.42_deadbeef.so").write_bytes(b"l" * 2000)
    (folder / f"{key}.lock").touch()
    (folder / "README").write_text("someone else's")
    assert main(["cache", "info", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert (info["entries"], info["files"], info["size_bytes"]) == (1, 3, 3000)
    assert info["directory"] == str(folder) and info["exists"]
    assert main(["cache", "clear"]) == 0
    assert capsys.readouterr().out == f"removed 3 files (2.9 KiB) from {folder}\n"
    assert [p.name for p in folder.iterdir()] == ["README"]


def test_clear_says_it_left_an_entry_being_compiled(folder, capsys):
    folder.mkdir(parents=True)
    key = "0123456789abcdef" * 4
    (folder / f"{key}.77_0123abcd.o").write_bytes(b"o" * 100)
    with locked(folder / f"{key}.lock"):  # another process's compile of that entry
        assert main(["cache", "clear"]) == 0
    assert capsys.readouterr().out == (
        f"removed 0 files (0 B) from {folder}; left 1 entry another process is compiling now "
        "(clear again once it is done)\n"
    )
    assert (folder / f"{key}.77_0123abcd.o").exists()
    (folder / f"{key}.lock").unlink()
    assert main(["cache", "clear"]) == 0  # its one file, once the compile is done
    assert capsys.readouterr().out == f"removed 1 file (100 B) from {folder}\n"  # not "1 files"


def test_info_json_takes_a_file_as_every_other_json_option(folder, tmp_path, capsys):
    """``--json`` was a flag printing to stdout, where every other command's ``--json`` names a file or -."""
    assert main(["cache", "info", "--json", "-"]) == 0
    on_stdout = json.loads(capsys.readouterr().out)
    report = tmp_path / "new" / "cache.json"
    assert main(["cache", "info", "--json", str(report)]) == 0
    assert capsys.readouterr().out == f"wrote {report}\n"
    assert json.loads(report.read_text()) == on_stdout and on_stdout["directory"] == str(folder)
    data = tmp_path / "data.csv"
    data.write_text("a,b\n")
    assert main(["cache", "info", "--json", str(data)]) == 2
    assert "is not a JSON report" in capsys.readouterr().err and data.read_text() == "a,b\n"


def test_clear_of_a_symlinked_cache_is_a_one_line_error(folder, tmp_path, capsys):
    target = tmp_path / "elsewhere"
    target.mkdir()
    folder.parent.mkdir()
    folder.symlink_to(target)
    assert main(["cache", "clear"]) == 2
    assert "symlink" in capsys.readouterr().err


def test_cache_needs_an_action(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["cache"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "the following arguments are required: ACTION" in err


# --- the --jit auto rule of crowdmpc sweep ------------------------------------------------------------------

SEVEN = (
    "constant_velocity,vanilla_lstm_eth,social_lstm_eth,social_lstm_soft_eth,social_gan_eth,social_lstm_synth,"
    "orca_oracle"
).split(",")


def test_auto_compiles_when_the_episodes_repay_the_compiles():
    from pipelines.commands.sweep_jit import jit_pays
    from pipelines.experiments.cells import EXPERIMENTS

    # Seven predictors share one joint NLP (8 s), 0.1 s saved an episode each: 12 episodes per cell repay it.
    swap = EXPERIMENTS["predictors"].with_predictors(SEVEN).cells()
    assert not jit_pays(swap, 2) and not jit_pays(swap, 11) and jit_pays(swap, 12)
    # Table II: a joint (8 s) and a local (2.3 s) NLP per crowd size, 0.1 + 0.19 s saved per episode pair.
    table2 = EXPERIMENTS["table2"].cells()
    assert not jit_pays(table2, 35) and jit_pays(table2, 36) and jit_pays(table2, 1000)
    assert not jit_pays(EXPERIMENTS["baselines"].cells(), 1000)  # nothing to compile


def test_auto_is_off_without_gcc_and_on_needs_it(monkeypatch):
    from pipelines.commands import sweep_jit
    from pipelines.errors import PipelineError
    from pipelines.experiments import worker
    from pipelines.experiments.cells import EXPERIMENTS

    experiment = EXPERIMENTS["predictors"].with_predictors(SEVEN)
    monkeypatch.setattr(worker, "jit_available", lambda: True)
    assert sweep_jit.choose_jit("auto", "--jit", experiment, None, 3, 100)
    assert not sweep_jit.choose_jit("auto", "--jit", experiment, None, 3, 2)
    assert sweep_jit.choose_jit("on", "--jit", experiment, None, 3, 2) and not sweep_jit.choose_jit(
        "off", "--jit", experiment, None, 3, 100
    )
    monkeypatch.setattr(worker, "jit_available", lambda: False)
    assert not sweep_jit.choose_jit("auto", "--jit", experiment, None, 3, 100)
    with pytest.raises(PipelineError, match="needs gcc"):
        sweep_jit.choose_jit("on", "--jit", experiment, None, 3, 100)


def test_a_cache_without_room_for_a_compile_is_refused_by_on_and_turns_auto_off(
    folder, tmp_path, monkeypatch, capsys
):
    """gcc's "No space left on device" failed every episode of a `--jit on` sweep, one error a compile, with
    gcc's messages over the terminal; auto chose such a run as readily."""
    import shutil

    from pipelines.commands import sweep_jit
    from pipelines.experiments import worker
    from pipelines.experiments.cells import EXPERIMENTS

    # the nearest folder that exists: the cache is made only when a compile comes
    assert cache_location.free_bytes() == shutil.disk_usage(tmp_path).free
    room = compile_cache.COMPILE_ROOM_BYTES
    monkeypatch.setattr(worker, "jit_available", lambda: True)
    experiment = EXPERIMENTS["predictors"].with_predictors(SEVEN)
    monkeypatch.setattr(cache_location, "free_bytes", lambda: room)
    assert sweep_jit.choose_jit("auto", "--jit", experiment, None, 3, 100)
    monkeypatch.setattr(cache_location, "free_bytes", lambda: room - 1)
    assert not sweep_jit.choose_jit("auto", "--jit", experiment, None, 3, 100)
    monkeypatch.setattr(cache_location, "free_bytes", lambda: room // 2)
    out = tmp_path / "sweep"
    args = [
        "sweep",
        "--experiment",
        "controllers",
        "--episodes-per-cell",
        "2",
        "--jit",
        "on",
        "--out",
        str(out),
    ]
    assert main(args) == 2
    assert capsys.readouterr().err == (
        f"crowdmpc sweep: error: --jit on: the compile cache {folder} has 32.0 MB free, under the 64 MB a "
        "compile may need: free space, set $CROWDMPC_CACHE to a folder with room, or use --jit off\n"
    )
    assert not out.exists()


def test_info_json_into_a_named_pipe_reaches_its_reader(folder, tmp_path, capsys):
    """The check that --json FILE can be written opened and closed it: a pipe's reader (`cat fifo`) took
    that for the end of an empty output, and the write of the document then waited for another for good."""
    import os
    import threading

    fifo = tmp_path / "info.fifo"
    os.mkfifo(fifo)
    read: list[bytes] = []
    reader = threading.Thread(target=lambda: read.append(fifo.read_bytes()), daemon=True)
    reader.start()

    try:
        with within(20, "cache info --json waited for a reader of the pipe"):
            assert main(["cache", "info", "--json", str(fifo)]) == 0
    finally:
        # let the reader's open return, if the command never opened the pipe; ENXIO: no reader holds it open
        # (the reader read the document and closed it, its thread not yet ended)
        if reader.is_alive():
            with contextlib.suppress(OSError):
                os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))
    reader.join(5)
    assert json.loads(read[0])["directory"] == str(folder)
    assert capsys.readouterr().out == f"wrote {fifo}\n"
