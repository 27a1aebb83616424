"""Config validation at its edges, against hand-computed values: the largest values allowed and the first
refused, booleans never taken for numbers, what an option chooses though it repeats the default, the
[env.orca] and formation settings reaching the simulator, and the default seeds."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from pipelines.config import ConfigError, load
from pipelines.config.command_line import Entry
from pipelines.config.entries import MAX_CONFIG_BYTES, Source


@pytest.mark.parametrize(
    ("setting", "message"),
    [
        ("world.dt=true", "--set world.dt: must be a finite number > 0, got True"),
        ("world.obs_len=true", "--set world.obs_len: must be an int in \\[1, 1000\\], got True"),
        (
            "env.orca.max_neighbors=true",
            "--set env.orca.max_neighbors: must be an int in \\[0, 1000\\], got True",
        ),
    ],
)
def test_a_boolean_is_no_number(setting, message):
    """TOML's true is a Python bool, which is an int: taken as 1 it would set dt = 1 s silently."""
    with pytest.raises(ConfigError, match=f"^{message}$"):
        load(sets=[setting])


def test_the_largest_horizon_is_allowed_and_the_next_refused():
    assert load(sets=["mpc.horizon=100"]).mpc.horizon == 100  # MOST["mpc.horizon"]
    with pytest.raises(ConfigError, match="^--set mpc.horizon: must be at most 100, got 101$"):
        load(sets=["mpc.horizon=101"])


def test_the_longest_episode_is_allowed_and_one_step_more_refused():
    # Paper profile, timeout margin 1 s: steps start at t = k * 0.01 < 1001 - 1 = 1000 s, k = 0..99999, so
    # 100000 steps (crowdsim.world.MOST_EPISODE_STEPS); a 1001.01 s limit gives 100001.
    assert load(sets=["world.dt=0.01", "env.time_limit=1001.0"]).env.max_steps == 100_000
    with pytest.raises(ConfigError, match="must be at most 100000 steps of dt = 0.01 s, got 1001.01 s"):
        load(sets=["world.dt=0.01", "env.time_limit=1001.01"])


def test_a_config_file_over_one_mebibyte_is_refused(tmp_path):
    path = tmp_path / "big.toml"
    path.write_text("#" * MAX_CONFIG_BYTES)  # a comment of exactly 1 MiB: still a config file
    assert load(str(path)).mpc.horizon == load().mpc.horizon
    path.write_text("#" * (MAX_CONFIG_BYTES + 1))
    with pytest.raises(ConfigError, match=f"{MAX_CONFIG_BYTES + 1} bytes; a config file is at most 1 MiB"):
        load(str(path))


def test_a_config_from_a_pipe_is_read_once_and_bounded_as_a_file(tmp_path):
    """A shell's ``--config <(...)`` (a pipe) was refused as "not a file"; it is read once, as a pipe can be
    (a second read would find it empty), and over 1 MiB it is refused as a file is."""
    import contextlib
    import os
    import threading

    pipe = tmp_path / "config.fifo"
    os.mkfifo(pipe)

    def write(text: str) -> None:
        with contextlib.suppress(BrokenPipeError):  # the refusal closes the pipe before the last bytes
            pipe.write_text(text)

    def written(text: str) -> threading.Thread:
        writer = threading.Thread(target=write, args=(text,), daemon=True)
        writer.start()
        return writer

    writer = written("[mpc]\nhorizon = 7\n")
    assert load(str(pipe)).mpc.horizon == 7
    writer.join(5)
    writer = written("#" * (MAX_CONFIG_BYTES + 2))
    with pytest.raises(ConfigError, match=r"config.fifo: more than 1 MiB from the pipe; a config file is at"):
        load(str(pipe))
    writer.join(5)
    assert not writer.is_alive()


def test_an_option_chooses_its_value_even_when_it_is_the_default(tmp_path: Path):
    """`--formation auto` is a choice (sweep_plan refuses options an experiment fixes); a file that states a
    default (as `config show` writes every key) chooses nothing, one that states another value does."""
    default = load().default("env", "formation")
    assert default == "auto"
    option = load(cli=[Entry("env", "formation", default, Source("cli", "--formation"))])
    assert option.chosen("env", "formation") and option.label("env", "formation") == "--formation"
    path = tmp_path / "run.toml"
    path.write_text('[env]\nformation = "auto"\n')
    assert not load(str(path)).chosen("env", "formation")
    path.write_text('[env]\nformation = "row"\n')
    assert load(str(path)).chosen("env", "formation")
    assert not load().chosen("env", "formation")  # nothing given


@pytest.mark.parametrize(
    "text, shown",
    [
        (
            "[simulate]\njson = 1979-05-27\n",
            "simulate.json: must not be a TOML date or time, got 1979-05-27 ",
        ),
        (
            "[mpc]\nw_coll = 1979-05-27T07:32:00\n",
            "mpc.w_coll: must not be a TOML date or time, got 1979-05-27T07",
        ),
        (
            "[scenario]\nhumans = [5, 07:32:00]\n",
            "scenario.humans: must not be a TOML date or time, got 07:32:00 ",
        ),
    ],
)
def test_a_toml_date_is_named_in_toml_not_as_a_python_repr(text, shown, tmp_path: Path):
    """No setting takes a date: the error showed Python's ``datetime.date(1979, 5, 27)`` to a TOML user."""
    path = tmp_path / "run.toml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=re.escape(shown)) as error:
        load(str(path))
    assert "datetime" not in str(error.value)


def test_a_set_value_that_tomllib_reads_as_a_date_is_the_word_given():
    """``--set simulate.json=2026-12-02`` names a file, as other bare words do; it was refused as a date."""
    assert load(sets=["simulate.json=2026-12-02"]).simulate.json == "2026-12-02"


def test_a_bare_number_for_a_text_setting_is_the_word_given():
    """``--set sweep.out=2026`` was "must be a path, got 2026" (and ``1e3`` "got 1000.0"), where ``--out
    2026`` names that folder; a number setting still reads the number, and a boolean stays refused."""
    config = load(sets=["sweep.out=2026", "simulate.json=1e3", "simulate.plot=1_000"])
    assert (config.sweep.out, config.simulate.json, config.simulate.plot) == ("2026", "1e3", "1_000")
    assert load(sets=["mpc.w_coll=1e3"]).mpc.w_coll == 1000.0
    with pytest.raises(ConfigError, match="^--set simulate.json: must be a path, got True;"):
        load(sets=["simulate.json=true"])


@pytest.mark.parametrize("where", ["file", "set"])
def test_a_date_inside_an_inline_table_or_a_set_array_is_named_in_toml(where, tmp_path: Path):
    """An inline table's date was shown as ``{'a': datetime.date(1979, 5, 27)}``, in a file and in --set."""
    if where == "file":
        path = tmp_path / "run.toml"
        path.write_text("[simulate]\njson = {a = 1979-05-27}\n")
        kwargs: dict = {"path": str(path)}
    else:
        kwargs = {"sets": ["simulate.json={a = 1979-05-27}"]}
    with pytest.raises(ConfigError, match="simulate.json: must not be a TOML date or time, got 1979-05-27 "):
        load(**kwargs)
    with pytest.raises(ConfigError, match="scenario.humans: must not be a TOML date or time, got 07:32:00 "):
        load(sets=["scenario.humans=[5, 07:32:00]"])


def test_env_orca_and_formation_reach_the_simulator():
    env = load(sets=["env.orca.max_neighbors=3", 'env.formation="wedge"']).env
    assert (env.orca.max_neighbors, env.formation) == (3, "wedge")


def test_the_default_seeds_are_zero():
    """Episode i of simulate uses seed 0 + i, a sweep's cells seeds 0 + i // 2: the runs the docs show."""
    cfg = load()
    assert (cfg.simulate.seed, cfg.sweep.seed, cfg.simulate.episodes) == (0, 0, 1)


@pytest.mark.parametrize(
    ("setting", "message"),
    [
        ("world.obs_len=1001", "world.obs_len: must be at most 1000, got 1001"),
        ("mpc.j_max=1001", "mpc.j_max: must be at most 1000, got 1001"),
        ("mpc.solver_max_iter=100001", "mpc.solver_max_iter: must be at most 100000, got 100001"),
        ("mpc.time_limit_s=3600.5", r"mpc.time_limit_s: must be at most 3600.0, got 3600.5"),
        ("env.orca.max_neighbors=1001", "env.orca.max_neighbors: must be at most 1000, got 1001"),
    ],
)
def test_numbers_that_size_the_work_have_a_ceiling(setting, message):
    """A typo of a few zeros would allocate a history of a billion rows or run an hour-long solve per step;
    each such number is refused one past its ceiling (keys.MOST, written out here by hand)."""
    with pytest.raises(ConfigError, match=f"^--set {message}$"):
        load(sets=[setting])


@pytest.mark.parametrize(
    ("key", "message"),
    [
        ("scenario.name", "scenario.name: must be one of ['circle', 'perpendicular'], got 'xxx"),
        ("controller.margins", "controller.margins: bad margins 'xxx"),
        ("mpc.horizon", "mpc.horizon: must be an integer >= 1, got 'xxx"),
        ("env.profile", "env.profile: unknown profile 'xxx"),
    ],
)
def test_an_error_line_shows_a_long_value_cut(key, message, tmp_path: Path):
    """The dataclasses' messages show the bad value in full: a 900 kB string in a file was a 900 kB error
    line. Cut as every other message cuts a value, to 80 characters."""
    section, name = key.rsplit(".", 1)
    path = tmp_path / "big.toml"
    path.write_text(f'[{section}]\n{name} = "{"x" * 900_000}"\n')
    with pytest.raises(ConfigError) as error:
        load(str(path))
    line = str(error.value)
    assert line.startswith(f"{path}: {message}") and "'" + "x" * 76 + "..." in line and len(line) < 400, line


def test_a_clash_of_two_chosen_values_names_one_of_them_not_a_bystander():
    """profile v1 and goal_assignment slots clash (slots needs the paper's success rule), each valid alone;
    the error named --set env.formation, the last key chosen, which takes no part in it."""
    sets = ["env.goal_assignment=slots", "env.profile=v1", "env.formation=row"]
    with pytest.raises(ConfigError, match=r"^--set env\.(goal_assignment|profile): EnvConfig\.goal_"):
        load(None, sets)


@pytest.mark.parametrize(
    "setting, message",
    [
        (
            'sweep.predictors=["constant_velocity", "constant_velocity"]',
            "--set sweep.predictors: must name each predictor once, got 'constant_velocity' more than once",
        ),
        (
            'sweep.controllers=["cmpc", "orca", "cmpc"]',
            "--set sweep.controllers: must name each controller once, got 'cmpc' more than once",
        ),
    ],
)
def test_a_swap_list_names_each_column_once(setting, message):
    """As sweep.humans does: config show printed the list, and the sweep refused it as "--set
    sweep.predictors: --predictors names [...] more than once", naming an option not given."""
    with pytest.raises(ConfigError, match=f"^{re.escape(message)}$"):
        load(None, [setting])


@pytest.mark.parametrize(
    "setting, message",
    [
        ("sweep.controllers=cmpc", 'like ["cmpc", "orca"], got \'cmpc\''),
        ("sweep.predictors=constant_velocity", 'like ["constant_velocity", "social_lstm_eth"], got'),
    ],
)
def test_a_list_of_names_is_asked_for_with_its_own_example(setting, message):
    """sweep.controllers asked for 'a list of names, like ["constant_velocity", "social_lstm_eth"]', the
    predictors', as its example."""
    with pytest.raises(ConfigError, match=f"must be a list of names, {re.escape(message)}"):
        load(None, [setting])


@pytest.mark.parametrize("bystander", ["env.orca.max_neighbors=5", "world.radius=0.25", "env.formation=row"])
def test_a_default_that_clashes_names_the_value_it_clashes_with(bystander):
    """[world] dt = 0.0001 makes the profile's 40 s episode 400000 steps; the error named whichever value was
    set after it (--set env.orca.max_neighbors, which takes no part), not --set world.dt."""
    with pytest.raises(ConfigError, match=r"^--set world\.dt: env\.time_limit \(unset: the paper profile's"):
        load(None, ["world.dt=0.0001", bystander])


@pytest.mark.parametrize("bystander", ["env.time_limit=1e-6", "env.formation=row"])
def test_an_earlier_section_that_breaks_this_one_is_named(bystander):
    """[world] dt = 1e-9 is below the least dt, whatever [env] holds; the error named the [env] value set
    beside it (it broke [env] 'alone', over that world), not --set world.dt. WorldFacts refuses it itself
    now (crowdsim.world.LEAST), as EnvConfig does."""
    with pytest.raises(ConfigError, match=r"^--set world\.dt: must be at least 1e-06 s, got 1e-09$"):
        load(None, ["world.dt=1e-9", bystander])


def test_config_show_notes_a_configuration_the_runs_refuse(tmp_path, capsys):
    """`config show` printed `[mpc] d_min = 0.5` and exited 0 where simulate then refused it (below the
    contact distance, a fact of [mpc] and [world] together): it still prints the file, with a note."""
    from pipelines.cli import main

    path = tmp_path / "close.toml"
    path.write_text("[mpc]\nd_min = 0.5\n")
    assert main(["config", "show", "--config", str(path)]) == 0
    out, err = capsys.readouterr()
    assert "d_min = 0.5" in out
    assert err.startswith(
        "note: simulate and sweep refuse this configuration: the MPC's d_min 0.5 m is below"
    )
    path.write_text("[mpc]\nd_min = 0.6\n")
    assert main(["config", "show", "--config", str(path)]) == 0
    assert capsys.readouterr().err == ""


def test_config_show_notes_fixed_margins_the_horizon_refuses(capsys):
    """`config show --set controller.margins=fixed:0.1` printed the file without a word, where simulate with
    cmpc and every sweep of a planning method refuse margins of another length than the horizon."""
    from pipelines.cli import main

    assert main(["config", "show", "--set", "controller.margins=fixed:0.1"]) == 0
    out, err = capsys.readouterr()
    assert 'margins = "fixed:0.1"' in out
    assert err == (
        "note: simulate and sweep refuse this configuration: fixed margins need one value per horizon step "
        "(4), got 1\n"
    )
    assert (
        main(["config", "show", "--set", "controller.margins=fixed:0.1,0.2", "--set", "mpc.horizon=2"]) == 0
    )
    assert capsys.readouterr().err == ""


def test_a_key_in_the_wrong_section_names_the_section_that_has_it(tmp_path):
    """`episodes` under [scenario] (a hand-edited demo file) listed [scenario]'s keys only; a near miss said
    "did you mean", a key of another section nothing."""
    path = tmp_path / "demo.toml"
    path.write_text("[scenario]\nepisodes = 4\n")
    with pytest.raises(
        ConfigError, match=r"scenario.episodes: unknown key \(a key of \[simulate\]\); valid keys"
    ):
        load(path)


def test_a_file_with_a_byte_order_mark_reads_as_without_one(tmp_path: Path):
    """Windows editors write one; tomllib refused it as "Invalid statement (at line 1, column 1)"."""
    path = tmp_path / "bom.toml"
    path.write_bytes(b"\xef\xbb\xbf[scenario]\nhumans = 3\n")
    assert load(path).scenario.humans == 3


def test_one_file_given_twice_by_two_spellings_is_one_file(tmp_path: Path, monkeypatch, capsys):
    """`--config a.toml simulate --config ./a.toml` was "--config given twice"; two files still are."""
    from pipelines.cli import main

    monkeypatch.chdir(tmp_path)
    (tmp_path / "a.toml").write_text("[scenario]\nhumans = 3\n", encoding="utf-8")
    (tmp_path / "b.toml").write_text("[scenario]\nhumans = 4\n", encoding="utf-8")
    assert main(["--config", "a.toml", "config", "show", "--config", "./a.toml"]) == 0
    assert "\nhumans = 3 " in capsys.readouterr().out
    assert main(["--config", "a.toml", "config", "show", "--config", "b.toml"]) == 2
    assert "--config given twice (a.toml, b.toml)" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("text", "message"),
    [  # each said it as its dataclass does: "True or False", "a bool"
        ('[mpc]\nwarm_start = "yes"\n', "x.toml: mpc.warm_start: must be true or false, got 'yes'"),
        (
            '[env]\nrobots_visible = "false"\n',
            "x.toml: env.robots_visible: must be true or false, got 'false'",
        ),
        (
            '[controller]\nflocking = "false"\n',
            "x.toml: controller.flocking: must be true or false, got 'false'",
        ),
        (  # the section meant is the last part, not the closest whole name ([controller])
            "[controller.mpc]\nhorizon = 3\n",
            "x.toml: [controller.mpc]: unknown section (did you mean [mpc]?); valid sections: [world], "
            "[env], [env.orca], [scenario], [controller], [mpc], [simulate], [sweep]",
        ),
    ],
)
def test_a_boolean_of_the_wrong_type_and_a_nested_section_are_named_in_tomls_words(text, message, tmp_path):
    path = tmp_path / "x.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError) as refused:
        load(path)
    assert str(refused.value) == message.replace("x.toml", str(path))


def test_a_sweep_refuses_recorded_iterations_it_would_not_record_and_cuts_long_values(tmp_path, capsys):
    """A sweep ran `record_iterations` without `--record` in silence, where simulate refuses it; a 900 kB
    predictor name for ORCA was a 900 kB error line."""
    from pipelines.cli import main

    sweep = ["sweep", "--experiment", "table2", "--humans", "3", "--dry-run", "--out", str(tmp_path / "s")]
    assert main(["--set", "controller.record_iterations=true", *sweep]) == 2
    assert capsys.readouterr().err == (
        "crowdmpc sweep: error: --set controller.record_iterations: the iterations are written to the MCAP "
        "recordings; give --record failures or all too (or [sweep] record)\n"
    )
    assert main(["--set", "controller.record_iterations=true", *sweep, "--record", "failures"]) == 0
    # a sweep reported (--report-only) is of its recorded config, which older code ran as it was
    from pipelines.commands.sweep_plan import check_iterations_recorded, check_world
    from pipelines.config import load

    recorded = load(sets=["controller.record_iterations=true", "sweep.experiment=table2"])
    check_world(recorded)
    with pytest.raises(ConfigError, match="the iterations are written to the MCAP recordings"):
        check_iterations_recorded(recorded)
    path = tmp_path / "long.toml"
    path.write_text(f'[controller]\npredictor = "{"a" * 900_000}"\n', encoding="utf-8")
    capsys.readouterr()
    assert main(["--config", str(path), "simulate", "--controller", "orca", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert len(err) < 400 and f"{path}: controller.predictor {'a' * 77}...: controller 'orca'" in err


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            'predictor = "nope"\n',
            "controller.predictor: unknown predictor 'nope'; choose from ['constant_velocity'",
        ),
        (
            'margins = "fixed:0.1,0.2"\n',
            "controller.margins: fixed margins need one value per horizon step (4), got 2",
        ),
        (
            "[mpc]\nd_min = 0.5\n",
            "mpc.d_min: the MPC's d_min 0.5 m is below the contact distance 2 x [world] radius",
        ),
        # the d_min is Table I's; the radius the file's is what leaves it inside a contact
        ("[world]\nradius = 1.0\n", "world.radius: the MPC's d_min 0.8 m is below the contact distance"),
        # a file `config show` wrote states Table I's d_min: the radius is still the value changed
        (
            "[mpc]\nd_min = 0.8\n[world]\nradius = 1.0\n",
            "world.radius: the MPC's d_min 0.8 m is below the contact distance",
        ),
        (
            'predictor = "social_lstm_eth"\n[world]\nobs_len = 3\n',
            "world.obs_len: the predictor social_lstm_eth reads 9 observed steps but the simulator keeps 3",
        ),
        # both wrong: the first the controller's check refuses is the one named
        (
            'predictor = "social_lstm_eth"\n[world]\nobs_len = 3\ndt = 0.2\n',
            "world.dt: the predictor social_lstm_eth reads positions sampled every 0.4 s",
        ),
    ],
)
def test_a_value_the_run_refuses_names_the_file_it_came_from(text, message, tmp_path, capsys):
    """These were refused as the controller was built, naming the key at most ("unknown predictor 'nope'")."""
    from pipelines.cli import main

    path = tmp_path / "x.toml"
    path.write_text('[controller]\ncontroller = "cmpc"\n' + text, encoding="utf-8")
    capsys.readouterr()
    assert main(["--config", str(path), "simulate", "--humans", "2", "--no-progress"]) == 2
    assert capsys.readouterr().err.startswith(f"crowdmpc simulate: error: {path}: {message}")


def test_fixed_margins_the_horizon_refuses_name_the_option_that_gave_them(capsys):
    """`simulate --margins fixed:0.1` was refused as "fixed margins need one value per horizon step (4), got
    1", naming no input (a file's or --set's margins were named)."""
    from pipelines.cli import main

    argv = ["simulate", "--controller", "cmpc", "--humans", "1", "--no-progress", "--margins", "fixed:0.1"]
    assert main(argv) == 2
    assert capsys.readouterr().err == (
        "crowdmpc simulate: error: --margins: fixed margins need one value per horizon step (4), got 1\n"
    )


@pytest.mark.parametrize(
    ("text", "options", "message"),
    [
        (
            '[controller]\npredictor = "nope"\n',
            [],
            "{path}: controller.predictor: experiment 'table2' needs predictors ['nope'] that are not",
        ),
        (
            '[controller]\nmargins = "fixed:0.1,0.2"\n',
            [],
            "{path}: controller.margins: method 'CMPC' of experiment 'table2': fixed margins need one value",
        ),
        (
            "[mpc]\nd_min = 0.5\n",
            [],
            "{path}: mpc.d_min: method 'CMPC' of experiment 'table2': the MPC's d_min 0.5 m is below",
        ),
        (
            '[sweep]\nvary = "mpc.d_min=0.5,1.0"\n',
            [],
            "{path}: sweep.vary: method 'CMPC d_min=0.5' of experiment 'table2': the MPC's d_min 0.5 m",
        ),
        ("", ["--margins", "fixed:0.1"], "--margins: method 'CMPC' of experiment 'table2': fixed margins"),
        (
            '[sweep]\npredictors = ["constant_velocity", "nope"]\n',
            ["--experiment", "predictors"],
            "{path}: sweep.predictors: experiment 'predictors' needs predictors ['nope'] that are not",
        ),
        # the column the vary adds is the one refused, not the margins every column shares
        (
            "",
            ["--margins", "conformal:0.1", "--vary", "mpc.horizon=4,6"],
            "--vary: method 'CMPC horizon=6' of experiment 'table2': the closed-loop calibration of",
        ),
    ],
)
def test_a_value_a_sweep_refuses_names_where_the_run_chose_it(text, options, message, tmp_path, capsys):
    """A sweep's plan checks named the method alone ("method 'CMPC' of experiment 'table2': fixed margins
    need ..."): a value a file chose looked like one of the experiment's own."""
    from pipelines.cli import main

    path = tmp_path / "x.toml"
    path.write_text(text, encoding="utf-8")
    sweep = ["sweep", "--experiment", "table2", "--humans", "3", "--dry-run", "--out", str(tmp_path / "s")]
    capsys.readouterr()
    assert main(["--config", str(path), *sweep, *options]) == 2
    last = capsys.readouterr().err.splitlines()[-1]  # after the notes on the columns that would run
    assert last.startswith(f"crowdmpc sweep: error: {message.format(path=path)}")
    assert main(sweep) == 0  # the experiment's own values pass
