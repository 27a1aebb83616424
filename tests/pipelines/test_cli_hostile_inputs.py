"""Hostile input at the command line, each refused in one line (exit 2) before any work: configs nested
past the recursion limit, world times that overflow, counts that would allocate or run for days, --set items
that smuggle in more TOML, repeated --config, symbolic-link loops, plugins that exit on import or come from
the environment, and a cache directory that cannot be one."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

from pipelines.cli import main
from predictors.data import locate
from tests.predictors.samples import write_tiny_ewap

EXITS = "tests.plugins.exits_on_import:Net"  # sys.exit(3) while imported
RAISES = "tests.plugins.raises_on_import:Net"  # ValueError("boom") while imported
INTERRUPTS = "tests.plugins.interrupts_on_import:Net"  # KeyboardInterrupt while imported
SIGNALLED = "tests.plugins.signalled_on_import:Net"  # SIGTERM or SIGHUP to itself while imported
IN_EXEC = "tests.plugins.signalled_in_exec:Net"  # the same inside exec() of a string, while imported
REPO = Path(__file__).resolve().parents[2]


def error_line(capsys, *argv: str) -> str:
    """The one line a refused command prints (exit 2, nothing on stdout): a parser error or a user error."""
    capsys.readouterr()
    try:
        code = main(list(argv))
    except SystemExit as exc:
        code = exc.code
    captured = capsys.readouterr()
    assert code == 2, captured.err
    assert captured.out == "", captured.out
    assert "Traceback" not in captured.err
    lines = captured.err.splitlines()
    assert len(lines) == 1, captured.err
    return lines[0]


def _no_work(monkeypatch) -> None:
    def started(*args, **kwargs):
        raise AssertionError("work started")

    monkeypatch.setattr("pipelines.loop.episode.run_episodes", started)
    monkeypatch.setattr("pipelines.experiments.synth.synthesize", started)


# ---- 1. nesting past the recursion limit ---------------------------------------------------------------
def test_a_config_file_nested_100_000_deep_is_one_line_naming_it(tmp_path, capsys):
    path = tmp_path / "deep.toml"
    path.write_text("a = " + "[" * 100_000 + "]" * 100_000 + "\n")  # 200 kB, under the 1 MiB cap
    line = error_line(capsys, "--config", str(path), "config", "show")
    assert (
        line == f"crowdmpc config show: error: {path}: not a config file: arrays or tables nested too deeply"
    )


def test_a_set_value_nested_past_the_recursion_limit_is_one_line_naming_it(capsys):
    line = error_line(capsys, "--set", "sweep.humans=" + "[" * 5000 + "]" * 5000, "config", "show")
    assert (
        line == "crowdmpc config show: error: --set sweep.humans: the value's arrays or tables are "
        "nested too deeply"
    )


def test_a_sweep_lists_each_crowd_size_at_most_once_and_shows_a_bad_list_short(capsys):
    line = error_line(capsys, "--set", f"sweep.humans={[5] * 51}", "config", "show")
    assert line == "crowdmpc config show: error: --set sweep.humans: must list at most 50 crowd sizes, got 51"
    line = error_line(capsys, "--set", "sweep.humans=" + "[" * 300 + "]" * 300, "config", "show")
    assert line.startswith(
        "crowdmpc config show: error: --set sweep.humans: must be a list of integers, like"
    )
    assert line.endswith("[[[...") and len(line) < 200, line


# ---- 2. world times that overflow --------------------------------------------------------------------
def test_a_step_longer_than_the_episode_is_refused_before_the_straight_controller_overflows(
    capsys, monkeypatch
):
    _no_work(monkeypatch)
    line = error_line(capsys, "--set", "world.dt=1e308", "simulate", "--controller", "straight")
    assert line.startswith("crowdmpc simulate: error: --set world.dt: ")
    assert line.endswith("dt must be at most time_limit = 40 s, got 1e+308")


def test_a_tiny_step_is_refused_with_compact_numbers(capsys, monkeypatch):
    _no_work(monkeypatch)
    line = error_line(capsys, "--set", "world.dt=1e-300", "simulate", "--controller", "straight")
    assert line.startswith("crowdmpc simulate: error: --set world.dt: ") and "1e-300" in line
    assert len(line) < 200, line  # once a 300-digit step count
    line = error_line(capsys, "--set", "world.dt=1e-5", "simulate", "--controller", "straight")
    assert line.endswith("must be at most 100000 steps of dt = 1e-05 s, got 40 s (3.9e+06 steps)"), line


@pytest.mark.parametrize(
    "item, message",
    [
        (f"mpc.w_coll=1{'0' * 400}", "--set mpc.w_coll: must be at most 1.8e+308 in magnitude, got 1000"),
        (f"mpc.w_coll=1{'0' * 5000}", "--set mpc.w_coll: an integer of more than 4300 digits"),
        (f"sweep.seed=0x{'f' * 5000}", "--set sweep.seed: an integer of more than 4300 digits"),
        (f"world.obs_len=0x{'f' * 5000}", "--set world.obs_len: an integer of more than 4300 digits"),
    ],
)
def test_an_integer_past_a_float_or_past_pythons_digit_limit_is_one_line(item, message, capsys):
    """An OverflowError (float(10**400)) and a ValueError (Python reads at most 4300 digits, TOML's 0x has no
    such limit but then no record can write it) ended config show in a traceback."""
    line = error_line(capsys, "--set", item, "config", "show")
    assert line.startswith(f"crowdmpc config show: error: {message}") and len(line) < 200, line


def test_a_config_file_with_an_integer_past_pythons_digit_limit_is_one_line(tmp_path, capsys):
    path = tmp_path / "big.toml"
    path.write_text(f"[mpc]\nw_coll = 1{'0' * 5000}\n")
    line = error_line(capsys, "--config", str(path), "config", "show")
    assert (
        line == f"crowdmpc config show: error: {path}: not a config file: an integer of more than 4300 digits"
    )


# ---- 3. and 4. counts that allocate or run for days ----------------------------------------------------
@pytest.mark.parametrize(
    "option, value, expected",
    [
        ("--top-k", "1000000000", "expected an integer in 1..1000, got 1000000000"),
        ("--top-k", "0", "expected an integer in 1..1000, got 0"),
        ("--seed", "-1", "expected an integer >= 0, got -1"),
    ],
)
def test_evaluate_bounds_its_counts_in_the_parser(option, value, expected, capsys):
    line = error_line(capsys, "evaluate", "--predictor", "social_gan_eth", option, value)
    assert line == (
        f"crowdmpc evaluate: error: argument {option}: {expected}; see 'crowdmpc evaluate --help'"
    )


@pytest.mark.parametrize(
    "option, value, expected",
    [
        ("--episodes", "1000000000", "expected an integer in 1..100000, got 1000000000"),
        ("--episodes", "0", "expected an integer in 1..100000, got 0"),
        ("--humans", "51", "expected an integer in 1..50, got 51"),
        ("--seed", "-1", "expected an integer >= 0, got -1"),
        ("--seed", "x" * 100, f"expected an integer >= 0, got {'x' * 40!r}"),
    ],
)
def test_data_synth_bounds_its_counts_in_the_parser(option, value, expected, tmp_path, capsys, monkeypatch):
    _no_work(monkeypatch)
    argv = {"--episodes": "1", "--humans": "7", "--seed": "0"} | {option: value}
    args = [item for pair in argv.items() for item in pair]
    line = error_line(capsys, "data", "synth", "--out", str(tmp_path / "s.ndjson"), *args)
    assert (
        line == f"crowdmpc data synth: error: argument {option}: {expected}; see 'crowdmpc data synth --help'"
    )


# ---- 5. --set items that smuggle in more TOML ----------------------------------------------------------
@pytest.mark.parametrize(
    "item",
    ['mpc.solver="ipopt"\nhorizon = 9', "mpc.horizon=4\n[bogus]\nx=1", "mpc\n.horizon=4", "mpc.horizon=4\r"],
)
def test_a_set_item_with_a_line_break_is_refused_naming_it(item, capsys):
    line = error_line(capsys, "--set", item, "config", "show")
    assert line == (
        f"crowdmpc config show: error: --set {item!r}: a line break or control character; one "
        "SECTION.KEY=VALUE per --set"
    )


def test_a_set_item_with_a_tab_still_works(capsys):
    assert main(["--set", "mpc.horizon=\t5", "config", "show"]) == 0
    assert "\nhorizon = 5 " in capsys.readouterr().out


# ---- 6. --config twice, symbolic-link loops, a file for a directory ----------------------------------
def _two_configs(tmp_path: Path) -> tuple[str, str]:
    a, b = tmp_path / "a.toml", tmp_path / "b.toml"
    a.write_text("[mpc]\nhorizon = 5\n")
    b.write_text("[mpc]\nhorizon = 6\n")
    return str(a), str(b)


def test_two_config_files_before_the_command_are_refused_like_one_before_and_one_after(tmp_path, capsys):
    a, b = _two_configs(tmp_path)
    expected = f"crowdmpc config show: error: --config given twice ({a}, {b}); one config file per run"
    assert error_line(capsys, "--config", a, "--config", b, "config", "show") == expected
    assert error_line(capsys, "--config", a, "config", "show", "--config", b) == expected
    assert error_line(capsys, "config", "show", "--config", a, "--config", b) == expected  # both after


@pytest.mark.parametrize("where", ["before", "after"])
def test_an_empty_config_path_is_refused_like_a_missing_file(where, capsys):
    """`--config ""` was dropped as no config at all, and the run went on with the defaults."""
    argv = ["--config", "", "config", "show"] if where == "before" else ["config", "show", "--config", ""]
    line = error_line(capsys, *argv)
    assert line == "crowdmpc config show: error: --config '': no such file (an empty path)"


@pytest.mark.parametrize(
    "argv, expected",
    [
        (["simulate", "--controller", "straight", "--json", ""], "crowdmpc simulate: error: --json must"),
        (["simulate", "--controller", "straight", "--plot", ""], "crowdmpc simulate: error: --plot must"),
        (["simulate", "--controller", "straight", "--record", ""], "crowdmpc simulate: error: --record must"),
        (["sweep", "--experiment", "baselines", "--out", ""], "crowdmpc sweep: error: --out must"),
        (["config", "show", "--from-sweep", ""], "crowdmpc config show: error: --from-sweep must"),
    ],
)
def test_an_empty_path_option_is_refused_by_name(argv, expected, tmp_path, capsys, monkeypatch):
    """argparse's type=Path read "" as ".": `--record ""` wrote MCAP files into the current directory, while
    the config file's `record = ""` was refused."""
    _no_work(monkeypatch)
    monkeypatch.chdir(tmp_path)
    line = error_line(capsys, *argv)
    assert line.startswith(expected) and ", got ''" in line, line
    assert list(tmp_path.iterdir()) == []


def test_one_config_file_given_twice_is_one(tmp_path, capsys):
    a, _ = _two_configs(tmp_path)
    assert main(["--config", a, "--config", a, "config", "show"]) == 0
    assert "\nhorizon = 5 " in capsys.readouterr().out


def test_a_config_symlink_loop_is_named_as_one(tmp_path, capsys):
    (tmp_path / "a.toml").symlink_to(tmp_path / "b.toml")
    (tmp_path / "b.toml").symlink_to(tmp_path / "a.toml")
    line = error_line(capsys, "--config", str(tmp_path / "a.toml"), "config", "show")
    assert line == f"crowdmpc config show: error: --config {tmp_path / 'a.toml'}: a symbolic-link loop"


def test_a_data_dir_that_is_a_file_or_a_loop_says_so(tmp_path, capsys):
    (tmp_path / "file").write_text("x")
    (tmp_path / "loop").symlink_to(tmp_path / "loop")
    for name, what in (("file", "is not a directory"), ("loop", "is a symbolic-link loop")):
        line = error_line(
            capsys, "evaluate", "--predictor", "constant_velocity", "--data-dir", str(tmp_path / name)
        )
        assert line == f"crowdmpc evaluate: error: data directory {tmp_path / name} {what}"


# ---- 7. plugins ----------------------------------------------------------------------------------------
def test_a_plugin_that_exits_on_import_is_one_line_naming_it(capsys):
    line = error_line(capsys, "--plugin", EXITS, "zoo", "list")
    assert line == (
        f"crowdmpc: error: argument --plugin: plugin {EXITS!r}: importing 'tests.plugins.exits_on_import' "
        "failed: it called sys.exit(3); a plugin module defines classes and must not exit; see "
        "'crowdmpc --help'"
    )


@pytest.mark.parametrize("variable", ["CROWDMPC_PLUGINS", "CROWDMPC_CONTROLLERS"])
@pytest.mark.parametrize("spec", [RAISES, EXITS])
def test_a_plugin_from_the_environment_that_fails_names_the_variable(variable, spec, capsys, monkeypatch):
    monkeypatch.setenv(variable, spec)
    module = spec.partition(":")[0]
    line = error_line(capsys, "train", "--model", spec)
    assert line.startswith(f"crowdmpc: error: ${variable}: plugin {spec!r}: importing {module!r} failed: ")
    assert module not in sys.modules


def test_ctrl_c_while_a_plugin_is_imported_is_not_swallowed(capsys):
    """Not reported as the plugin's failure to import: an interrupt, one line, exit 130 (as Ctrl-C anywhere
    before a command runs)."""
    assert main(["--plugin", INTERRUPTS, "zoo", "list"]) == 130
    assert capsys.readouterr().err == "crowdmpc zoo: interrupted\n"


@pytest.mark.parametrize("plugin", [SIGNALLED, IN_EXEC])
@pytest.mark.parametrize("name", ["SIGTERM", "SIGHUP", "SIGINT"])
def test_kill_before_a_command_runs_stops_as_ctrl_c_does(name, plugin):
    """`kill` (`timeout`, a closed terminal) in the first second or two, while the commands and plugins are
    imported, ended the process by the signal's default action: no line, where a Ctrl-C then prints
    "crowdmpc zoo: interrupted"; it is taken as Ctrl-C from the start, with 128 + the signal. And an interrupt
    raised in code run from a string (IN_EXEC; a dataclass's generated methods) ended the process by SIGINT
    once the CLI had exited 143 or 129 (CPython's note of an unhandled KeyboardInterrupt): a shell saw 130."""
    import signal
    import subprocess

    done = subprocess.run(
        [sys.executable, "-m", "pipelines.cli", "--plugin", plugin, "zoo", "list"],
        cwd=REPO,
        env=os.environ | {"CROWDMPC_TEST_SIGNAL": name},
        # as a shell starts it: a test run in the background (nohup, `make test &`) has SIGINT, SIGHUP ignored
        preexec_fn=lambda: signal.signal(getattr(signal, name), signal.SIG_DFL),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert (done.returncode, done.stderr) == (128 + getattr(signal, name), "crowdmpc zoo: interrupted\n")


# ---- 8. a cache directory that cannot be one -----------------------------------------------------------
def test_cache_info_says_a_file_is_no_cache_directory(tmp_path, capsys, monkeypatch):
    (tmp_path / "file").write_text("x")
    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path / "file"))
    expected = (
        f"$CROWDMPC_CACHE={tmp_path / 'file'}: {tmp_path / 'file'} is not a directory; "
        "set $CROWDMPC_CACHE to a writable directory"
    )
    assert error_line(capsys, "cache", "info") == f"crowdmpc cache info: error: {expected}"
    assert error_line(capsys, "cache", "clear") == f"crowdmpc cache clear: error: {expected}"


def test_evaluate_on_raw_data_refuses_an_unusable_cache_before_preparing(tmp_path, capsys, monkeypatch):
    raw_root = tmp_path / "data"
    write_tiny_ewap(raw_root)
    (tmp_path / "file").write_text("x")
    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path / "file" / "cache"))

    def prepare(*args, **kwargs):
        raise AssertionError("preparing into an unusable cache")

    monkeypatch.setattr(locate, "prepare_ewap", prepare)
    line = error_line(
        capsys, "evaluate", "--predictor", "constant_velocity", "--data-dir", str(raw_root), "--no-progress"
    )
    assert line == (
        f"crowdmpc evaluate: error: $CROWDMPC_CACHE={tmp_path / 'file' / 'cache'}: "
        f"{tmp_path / 'file'} is not a directory; set $CROWDMPC_CACHE to a writable directory"
    )
    assert os.path.isfile(tmp_path / "file")


def test_no_command_is_usage_on_stderr(capsys):
    """`crowdmpc` alone printed its whole help on stdout (exit 2), where every subcommand missing its action
    says so on stderr: a script piping stdout got 60 lines of help as output."""
    from pipelines.cli import main

    assert main([]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.startswith("usage: crowdmpc") and err.endswith("error: give a COMMAND (above)\n")


# ---- 9. paths holding control characters -----------------------------------------------------------------
@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (
            ["--config", "{d}/a\nb.toml", "simulate"],
            "crowdmpc simulate: error: --config {d}/a\\nb.toml: no such file",
        ),
        (
            ["sweep", "--experiment", "controllers", "--reuse", "{d}/a\nb", "--out", "{d}/o"],
            "crowdmpc sweep: error: --reuse {d}/a\\nb: not a sweep folder "
            "({d}/a\\nb/sweep.json does not exist)",
        ),
        (
            ["review", "{d}/x\r\x1b[2Ky.mcap"],
            "crowdmpc review: error: {d}/x\\r\\x1b[2Ky.mcap: no such recording",
        ),
        (
            ["simulate", "--bogus", "a\u2028b"],
            "crowdmpc simulate: error: unrecognized arguments: --bogus a\\u2028b; "
            "see 'crowdmpc simulate --help'",
        ),
    ],
)
def test_a_path_with_a_line_break_stays_on_the_error_line_escaped(argv, expected, tmp_path, capsys):
    """`crowdmpc --config $'a\\nb.toml' simulate` printed its error line over two lines: the CLI now writes
    control characters (and U+2028) of its error line as Python escapes, the rest as it was."""
    line = error_line(capsys, *(a.format(d=tmp_path) for a in argv))
    assert line == expected.format(d=tmp_path)
