"""Config files: the TOML schema over the frozen dataclasses, precedence (defaults < file < --set <
options), one-line errors naming file, key and expected value, `config show` round trips, the effective config
in simulate's JSON and MCAP metadata and in sweep records, and docs/examples/demo.toml reproducing `make
demo`."""

from __future__ import annotations

import dataclasses
import json
import re
import shlex
import tomllib
from pathlib import Path

import pytest

from crowdsim.env import EnvConfig
from crowdsim.orca import OrcaParams
from crowdsim.world import WorldFacts
from mpc.config import MPCConfig
from pipelines.cli import main
from pipelines.config import ConfigError, load
from pipelines.config.schema import (
    ENV_FROM_WORLD,
    MPC_EXCLUDED,
    SECTION_BY_NAME,
    SECTIONS,
)

REPO = Path(__file__).resolve().parents[2]
DEMO_TOML = REPO / "docs" / "examples" / "demo.toml"
SECTION_OBJECTS = ("world", "orca", "env", "scenario", "controller", "mpc", "simulate", "sweep")


def _objects(cfg) -> dict:
    return {name: getattr(cfg, name) for name in SECTION_OBJECTS}


def _write(tmp_path: Path, text: str, name: str = "run.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def _one_error_line(capsys, command: str) -> str:
    """The one line a user error prints, ``crowdmpc <command>: error: ...``; nothing on stdout."""
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    assert len(lines) == 1, captured.err
    assert lines[0].startswith(f"crowdmpc {command}: error: "), lines[0]
    assert captured.out == "", captured.out
    return lines[0].removeprefix(f"crowdmpc {command}: error: ")


# ----------------------------------------------------------------------------------------------------------
# The schema: every dataclass field has its key (or a stated home), every key a comment
# ----------------------------------------------------------------------------------------------------------


def test_every_field_of_the_dataclasses_has_a_key_or_a_stated_home():
    keys = {s.name: set(s.names) for s in SECTIONS}
    assert keys["world"] == {f.name for f in dataclasses.fields(WorldFacts)}
    assert keys["env.orca"] == {f.name for f in dataclasses.fields(OrcaParams)}
    env_fields = {f.name for f in dataclasses.fields(EnvConfig)}
    assert keys["env"] | set(ENV_FROM_WORLD) | {"orca"} == env_fields
    assert keys["mpc"] | set(MPC_EXCLUDED) == {f.name for f in dataclasses.fields(MPCConfig)}
    # the keys set elsewhere are refused with where they go
    assert set(SECTION_BY_NAME["mpc"].elsewhere) == set(MPC_EXCLUDED)
    assert set(SECTION_BY_NAME["env"].elsewhere) == set(ENV_FROM_WORLD)
    for section in SECTIONS:
        for key in section.keys:
            assert key.note, f"{section.name}.{key.name} has no comment"


def test_config_show_prints_the_annotated_defaults_and_loads_back_to_them(tmp_path, capsys):
    assert main(["config", "show"]) == 0
    text = capsys.readouterr().out
    tomllib.loads(text)  # valid TOML
    for line in text.splitlines():  # every key has its comment
        if line and not line.startswith("#") and not line.startswith("["):
            assert "  # " in line, line
    # the paper's Table I, annotated
    assert "w_coll = 1e7" in text and "(Table I: 1e7)" in text
    assert "horizon = 4" in text and "(Table I: 4)" in text
    assert "dt = 0.4" in text and "(Table I: 0.4 s)" in text
    assert "# controller = " in text  # no default: commented out
    path = _write(tmp_path, text)
    assert _objects(load(str(path))) == _objects(load())
    assert load(str(path)).mpc_overrides() == ()


def test_config_show_of_a_file_and_sets_is_the_effective_config_and_loads_back(tmp_path, capsys):
    path = _write(tmp_path, '[mpc]\nw_coll = 1e6\n\n[env]\nprofile = "v1"\ntime_limit = 25\n')
    sets = ["--set", "scenario.humans=5", "--set", "controller.margins=conformal:0.05"]
    argv = ["config", "show", "--config", str(path), *sets]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "w_coll = 1e6" in text and "humans = 5" in text and 'margins = "conformal:0.05"' in text
    assert "time_limit = 25.0" in text and "# timeout_margin = 0.0" in text  # v1's, unset
    shown = _write(tmp_path, text, "shown.toml")
    effective = load(str(path), ["scenario.humans=5", "controller.margins=conformal:0.05"])
    assert _objects(load(str(shown))) == _objects(effective)
    assert effective.env.time_limit == 25.0 and effective.env.success_rule == "first_reach"
    assert effective.env.goal_assignment == "fixed"  # the paper's task unless asked
    assert load(None, ["env.goal_assignment=slots"]).env.goal_assignment == "slots"
    with pytest.raises(ConfigError, match="env.goal_assignment: .*'slots' needs success_rule 'simultaneous'"):
        load(str(path), ["env.goal_assignment=slots"])  # v1's first_reach rule
    # the global options work as well
    assert main(["--config", str(path), "--set", "scenario.humans=5", "config", "show"]) == 0
    assert "humans = 5" in capsys.readouterr().out


def test_config_show_writes_any_text_so_that_it_loads_back(tmp_path, capsys):
    """json.dumps wrote an emoji as a UTF-16 surrogate pair (\\ud83d\\ude00), which TOML refuses, and left DEL
    as it is, which TOML refuses too: what config show printed did not load back."""
    path, shown = tmp_path / "run.toml", tmp_path / "shown.toml"
    path.write_text(
        '[simulate]\nrecord = "runs/\U0001f600 \\u007f\\u0000\\t\\"q\\\\ \\n"\n', encoding="utf-8"
    )
    assert load(str(path)).simulate.record == 'runs/\U0001f600 \x7f\x00\t"q\\ \n'
    assert main(["config", "show", "--config", str(path)]) == 0
    shown.write_text(capsys.readouterr().out, encoding="utf-8")
    assert "runs/\U0001f600" in shown.read_text(encoding="utf-8")
    assert main(["config", "show", "--config", str(shown)]) == 0
    assert capsys.readouterr().out == shown.read_text(encoding="utf-8")
    assert _objects(load(str(shown))) == _objects(load(str(path)))


def test_a_leading_tilde_in_a_path_setting_is_the_home_directory(tmp_path, capsys, monkeypatch):
    """No shell reads a config file (nor a quoted --set): `record = "~/runs"` wrote a folder named ~ in the
    current directory while the message said "wrote ... to ~/runs"."""
    home, work = tmp_path / "home", tmp_path / "work"
    home.mkdir(), work.mkdir()
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.chdir(work)
    sets = ["simulate.json=~/a.json", "simulate.plot=~/a.png", "simulate.record=~/runs", "sweep.out=~/sw"]
    cfg = load(sets=sets)
    assert (cfg.simulate.json, cfg.simulate.plot) == (str(home / "a.json"), str(home / "a.png"))
    assert (cfg.simulate.record, cfg.sweep.out) == (str(home / "runs"), str(home / "sw"))
    assert cfg.values["simulate"]["record"] == "~/runs"  # config show writes what was given
    path = _write(tmp_path, '[controller]\ncontroller = "straight"\n[simulate]\nrecord = "~/runs"\n')
    argv = ["--config", str(path), "simulate", "--humans", "0", "--no-progress"]
    assert main(argv) == 0
    assert f"wrote 1 MCAP file(s) to {home / 'runs'}" in capsys.readouterr().out
    assert list(work.iterdir()) == [] and len(list((home / "runs").glob("*.mcap"))) == 1


@pytest.mark.parametrize("home", ["", "relative/home"])
def test_a_leading_tilde_under_a_home_that_is_no_absolute_path(tmp_path, monkeypatch, home):
    """expanduser takes an empty $HOME for "/": `env HOME= crowdmpc` made `record = "~/runs"` /runs, which a
    run as root wrote into; a relative one made it a folder of the current directory. The password
    database's home is taken, as for no $HOME; without one, the setting is refused naming itself."""
    import pwd
    from types import SimpleNamespace

    monkeypatch.setenv("HOME", home)
    monkeypatch.setattr(pwd, "getpwuid", lambda uid: SimpleNamespace(pw_dir=str(tmp_path / "pw")))
    cfg = load(sets=["simulate.record=~/runs", "sweep.out=~//sw"])
    assert (cfg.simulate.record, cfg.sweep.out) == (
        str(tmp_path / "pw" / "runs"),
        str(tmp_path / "pw" / "sw"),
    )
    monkeypatch.setattr(pwd, "getpwuid", lambda uid: SimpleNamespace(pw_dir=""))
    with pytest.raises(ConfigError) as refused:
        load(sets=["simulate.record=~/runs"])
    assert str(refused.value) == (
        "--set simulate.record: cannot find the home directory for record ~/runs (no absolute $HOME, and "
        "none in the password database); set record to an absolute path"
    )


def test_set_null_unsets_a_key_a_file_sets(tmp_path, capsys, monkeypatch):
    """TOML has no null: `--set simulate.plot=` was no TOML value and `=none` a figure of no type, so a config
    file's plot could not be switched off. `--set KEY=null` unsets the key (in order with the other --set
    items); a quoted "null" is the string."""
    path = _write(tmp_path, '[controller]\ncontroller = "straight"\n[simulate]\nplot = "ep.png"\n')
    cfg = load(str(path), sets=["simulate.plot=null", "mpc.horizon=9", "mpc.horizon=null"])
    assert cfg.simulate.plot is None and cfg.source("simulate", "plot") is None
    assert cfg.mpc.horizon == MPCConfig().horizon and not cfg.chosen("mpc", "horizon")
    assert load(str(path), sets=["simulate.plot=null", "simulate.plot=b.png"]).simulate.plot == "b.png"
    assert main(["--config", str(path), "--set", "simulate.plot=null", "config", "show"]) == 0
    assert '\n# plot = "runs/episode.png"' in capsys.readouterr().out
    with pytest.raises(ConfigError) as refused:
        load(str(path), sets=['simulate.plot="null"'])
    assert str(refused.value).startswith("--set simulate.plot: must be a path, got 'null'; to switch it off")
    monkeypatch.chdir(tmp_path)
    argv = [
        "--config",
        str(path),
        "--set",
        "simulate.plot=null",
        "simulate",
        "--humans",
        "0",
        "--no-progress",
    ]
    assert main(argv) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.toml"]  # no ep.png


@pytest.mark.parametrize("name", ["json", "plot", "record"])
@pytest.mark.parametrize("word", ["none", "None", "null"])
def test_none_for_a_path_says_how_to_switch_it_off(tmp_path, name, word):
    """`--set simulate.record=none` recorded into a folder named none (as [sweep] record reads it, it meant
    off), `plot = "none"` was a figure of no type: each is refused saying how to switch the path off;
    ./none is the path of that name, and an empty path says so too."""
    path = _write(tmp_path, f'[simulate]\n{name} = "{word}"\n')
    with pytest.raises(ConfigError) as refused:
        load(str(path))
    assert str(refused.value) == (
        f"{path}: simulate.{name}: must be a path, got {word!r}; to switch it off, leave it out or unset it "
        f"(--set simulate.{name}=null); ./{word} is the path of that name"
    )
    assert getattr(load(sets=[f"simulate.{name}=./{word}"]).simulate, name) == f"./{word}"
    with pytest.raises(ConfigError) as refused:
        load(sets=[f'simulate.{name}=""'])
    assert str(refused.value) == (
        f"--set simulate.{name}: must be a path, got ''; to switch it off, leave it out or unset it "
        f"(--set simulate.{name}=null)"
    )
    with pytest.raises(ConfigError) as refused:
        load(sets=[f"simulate.{name}="])
    assert str(refused.value) == (
        f"--set simulate.{name}: '' is not a TOML value (e.g. 1e6, true, \"circle\", [5, 6]; null unsets "
        "the key)"
    )


def test_precedence_defaults_file_set_options(tmp_path):
    from pipelines.config.entries import Entry, Source

    path = str(_write(tmp_path, "[scenario]\nhumans = 5\nrobots = 2\n"))
    assert load().scenario.humans == 7
    assert load(path).scenario.humans == 5
    assert load(path, ["scenario.humans=6"]).scenario.humans == 6
    assert load(path, ["scenario.humans=6", "scenario.humans=4"]).scenario.humans == 4  # in order
    option = Entry("scenario", "humans", 8, Source("cli", "--humans"))
    cfg = load(path, ["scenario.humans=6"], [option])
    assert cfg.scenario.humans == 8 and cfg.scenario.robots == 2


def test_the_command_line_overrides_the_file(tmp_path, capsys):
    path = _write(
        tmp_path, '[controller]\ncontroller = "straight"\n[scenario]\nhumans = 2\n[simulate]\nseed = 3\n'
    )
    out = tmp_path / "run.json"
    argv = ["--config", str(path), "simulate", "--humans", "1", "--json", str(out), "--no-progress"]
    assert main(argv) == 0
    payload = json.loads(out.read_text())
    assert payload["run"]["humans"] == 1 and payload["run"]["seed"] == 3
    assert [e["n_humans"] for e in payload["episodes"]] == [1]
    assert payload["run"]["controller"] == "straight"
    assert {"commit", "dirty", "version", "casadi"} <= set(payload["code"])  # the code behind the numbers


@pytest.mark.parametrize("profile", ["paper", "v1"])
@pytest.mark.parametrize("visibility", ["visible", "invisible"])
def test_the_env_section_builds_the_profiles_own_config(profile, visibility):
    from crowdsim.profiles import make_env_config

    items = [f"env.profile={profile}", f"env.robots_visible={str(visibility == 'visible').lower()}"]
    assert load(None, items).env == make_env_config(profile, visibility)


def test_world_facts_reach_the_simulator_and_the_mpc_from_one_place(tmp_path):
    from pipelines.loop.mpc import mpc_config

    cfg = load(str(_write(tmp_path, "[world]\na_max = 3.0\nv_max = 1.5\nradius = 0.25\n")))
    assert (cfg.env.a_max, cfg.env.v_max, cfg.env.radius) == (3.0, 1.5, 0.25)
    assert (cfg.mpc.a_max, cfg.mpc.v_max) == (3.0, 1.5)
    assert cfg.env.world() == cfg.world
    # the closed loop builds the MPC from the simulator's world: the same numbers
    assert mpc_config(_spec(cfg), world=cfg.env.world()).a_max == 3.0
    assert cfg.mpc_overrides() == ()  # nothing in [mpc] differs from Table I in this world


def _spec(cfg):
    from pipelines.loop.spec import ControllerSpec

    return ControllerSpec("cmpc", mpc_overrides=cfg.mpc_overrides())


def test_mpc_overrides_are_the_values_that_differ_from_table_i(tmp_path):
    cfg = load(None, ["mpc.w_coll=1e6", "mpc.horizon=4", "mpc.solver=ipopt"])
    assert cfg.mpc_overrides() == (("w_coll", 1e6), ("solver", "ipopt"))
    assert cfg.mpc.w_coll == 1e6 and isinstance(cfg.mpc.w_coll, float)
    assert load(None, ["mpc.w_goal=20"]).mpc.w_goal == 20.0  # a TOML integer where a float is expected


# ----------------------------------------------------------------------------------------------------------
# Errors: one line naming the file (or --set, or the option), the key and what is expected
# ----------------------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "text, message",
    [
        ('[mpc]\nhorizon = "four"\n', "run.toml: mpc.horizon: must be an integer >= 1, got 'four'"),
        ("[mpc]\nhorizon = 0\n", "run.toml: mpc.horizon: must be an integer >= 1, got 0"),
        ("[mpc]\nw_coll = -1\n", "run.toml: mpc.w_coll: must be > 0, got -1.0"),
        (
            '[mpc]\nsolver = "gurobi"\n',
            "run.toml: mpc.solver: must be one of ('fatrop', 'ipopt'), got 'gurobi'",
        ),
        ("[world]\ndt = 0\n", "run.toml: world.dt: must be a finite number > 0, got 0.0"),
        ('[env]\ncrossing = "x"\n', "run.toml: env.crossing: must be one of ['paper', 'v1'], got 'x'"),
        (
            '[env]\nprofile = "v2"\n',
            "run.toml: env.profile: unknown profile 'v2'; choose from ['paper', 'v1']",
        ),
        ("[env]\nrobots_visible = 1\n", "run.toml: env.robots_visible: must be true or false, got 1"),
        (
            '[env]\ngoal_assignment = "swap"\n',
            "run.toml: env.goal_assignment: must be one of ['fixed', 'slots'], got 'swap'",
        ),
        (
            '[env.orca]\nneighbor_dist = "far"\n',
            "run.toml: env.orca.neighbor_dist: must be a number > 0 and at most 1e+06 m, or inf (every "
            "agent), got 'far'",
        ),
        ("[scenario]\nhumans = 100\n", "run.toml: scenario.humans: n_humans must be in [0, 50], got 100"),
        ("[scenario]\nrobots = 0\n", "run.toml: scenario.robots: must be in 1..12, got 0"),
        (
            '[scenario]\nname = "square"\n',
            "run.toml: scenario.name: must be one of ['circle', 'perpendicular'], got 'square'",
        ),  # fmt: skip
        ("[simulate]\nepisodes = 0\n", "run.toml: simulate.episodes: must be >= 1, got 0"),
        # a float was "must be >= 1, got 2.0" (and seed "must be >= 0, got 5.0"): a bound the value keeps
        ("[simulate]\nepisodes = 2.0\n", "run.toml: simulate.episodes: must be an integer, got 2.0"),
        ("[simulate]\nseed = 5.0\n", "run.toml: simulate.seed: must be an integer, got 5.0"),
        ("[scenario]\nrobots = 2.0\n", "run.toml: scenario.robots: must be an integer, got 2.0"),
        (
            "[sweep]\nepisodes_per_cell = 2.0\n",
            "run.toml: sweep.episodes_per_cell: must be an integer, got 2.0",
        ),
        ("[sweep]\nseed = 1.5\n", "run.toml: sweep.seed: must be an integer, got 1.5"),
        ("[sweep]\nhumans = [5.0]\n", "run.toml: sweep.humans: must list positive integers, got [5.0]"),
        ("[sweep]\nhumans = [5, 60]\n", "run.toml: sweep.humans: must be in 1..50, got 60"),
        (
            '[sweep]\nhumans = "5,6"\n',
            "run.toml: sweep.humans: must be a list of integers, like [5, 6, 7], got '5,6'",
        ),  # fmt: skip
        (
            "[env]\ntime_limit = 0.5\n",
            "run.toml: env.time_limit: env.timeout_margin (unset: the paper profile's 1.0): "
            "must be in [0, time_limit=0.5) s, got 1.0",
        ),  # fmt: skip
    ],
)
def test_a_bad_value_is_one_line_naming_file_key_and_expectation(
    text, message, tmp_path, capsys, monkeypatch
):
    monkeypatch.chdir(tmp_path)
    _write(tmp_path, text)
    assert main(["--config", "run.toml", "simulate", "--controller", "orca", "--no-progress"]) == 2
    assert _one_error_line(capsys, "simulate") == message


@pytest.mark.parametrize(
    "text, message",
    [
        (
            "[mpc]\nhorizn = 4\n",
            "run.toml: mpc.horizn: unknown key (did you mean 'horizon'?); valid keys: horizon, w_goal, ",
        ),  # fmt: skip
        (
            "[mcp]\nhorizon = 4\n",
            "run.toml: [mcp]: unknown section; valid sections: [world], [env], [env.orca], ",
        ),
        # a key above every table is no section: it belongs under its own
        ("horizon = 4\n", "run.toml: horizon: a key outside any section; put it under its section ([mpc])"),
        (
            'record = "runs/x"\n[mpc]\n',
            "run.toml: record: a key outside any section; put it under its section ([simulate] or [sweep])",
        ),  # fmt: skip
        (
            'controller = "cmpc"\n',
            "run.toml: controller: a key outside any section; put it under its section ([controller])",
        ),  # fmt: skip
        (
            "horizn = 4\n",
            "run.toml: horizn: a key outside any section, and no section has it (did you mean 'horizon' of "
            "[mpc]?); valid sections: [world], [env], ",
        ),  # fmt: skip
        (
            '["env.orca"]\nneighbor_dist = 5.0\n',
            'run.toml: ["env.orca"] names no section: write [env.orca], without quotes',
        ),  # fmt: skip
        ("[mpc]\ndt = 0.2\n", "run.toml: mpc.dt: not a [mpc] key: set it in [world]"),
        (
            "[mpc]\nhuman_margins = [0.1]\n",
            "run.toml: mpc.human_margins: not a [mpc] key: set margins in [controller] margins",
        ),  # fmt: skip
        ("[env]\nhistory_len = 8\n", "run.toml: env.history_len: not a [env] key: set [world] obs_len"),
        (
            "[mpc]\nhorizon = 4\nw_coll = = 1\n",
            "run.toml: not valid TOML: Invalid value (at line 3, column 10)",
        ),
        (
            "[mpc]\nhorizon = 4\n[mpc]\n",
            "run.toml: not valid TOML: Cannot declare ('mpc',) twice (at line 3, column 5)",
        ),
        ("mpc = 3\n", "run.toml: mpc: must be a table ([mpc]), got 3"),
        # a misspelt sub-table was "env.orcaa: unknown key; valid keys: profile, ...", which lists no table
        (
            "[env.orcaa]\nneighbor_dist = 5.0\n",
            "run.toml: [env.orcaa]: unknown section (did you mean [env.orca]?); valid sections: [world], ",
        ),  # fmt: skip
        ("[mpc.fatrop]\ntol = 1\n", "run.toml: [mpc.fatrop]: unknown section; valid sections: [world], "),
    ],
)
def test_a_bad_key_section_or_syntax_is_one_line(text, message, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _write(tmp_path, text)
    assert main(["simulate", "--config", "run.toml", "--controller", "orca", "--no-progress"]) == 2
    assert _one_error_line(capsys, "simulate").startswith(message)


@pytest.mark.parametrize(
    "item, message",
    [
        ("mpc.horizon=0", "--set mpc.horizon: must be an integer >= 1, got 0"),
        ("mpc.horizon=four", "--set mpc.horizon: must be an integer >= 1, got 'four'"),
        ("mpc.w_coll=", "--set mpc.w_coll: '' is not a TOML value"),
        ("mpc.w_coll", "--set 'mpc.w_coll': expected SECTION.KEY=VALUE, e.g. mpc.w_coll=1e6"),
        ("horizon=4", "--set 'horizon=4': expected SECTION.KEY=VALUE"),
        ("mpc.horizn=4", "--set mpc.horizn: unknown key (did you mean 'horizon'?)"),
        (  # a section set whole: its keys are listed, not [env]'s, which name no orca
            "env.orca={max_neighbors=5}",
            "--set env.orca: [env.orca] is a section; set one of its keys at a time, --set "
            "env.orca.KEY=VALUE (keys: neighbor_dist, max_neighbors, time_horizon)",
        ),
        ("controller.margins=bogus", "--set controller.margins: bad margins 'bogus'"),
        (
            "controller.coupling=mpc",
            "--set controller.coupling: must be one of ['ibr', 'nlp', 'none'], got 'mpc'",
        ),
    ],
)
def test_a_bad_set_item_is_one_line(item, message, capsys):
    assert main(["simulate", "--controller", "orca", "--no-progress", "--set", item]) == 2
    assert _one_error_line(capsys, "simulate").startswith(message)


def test_a_history_shorter_than_the_predictor_reads_names_world_obs_len(capsys):
    """The error told the user to set history_len, which [env] refuses ("set [world] obs_len"); `config
    show` said obs_len is what the predictors read, while each reads its own count of what it keeps."""
    argv = ["simulate", "--controller", "cmpc", "--humans", "1", "--no-progress", "--set", "world.obs_len=1"]
    assert main(argv) == 2
    assert _one_error_line(capsys, "simulate") == (
        "--set world.obs_len: the predictor constant_velocity reads 2 observed steps but the simulator keeps "
        "1 ([world] obs_len): set [world] obs_len >= 2 (e.g. --set world.obs_len=2)"
    )
    assert main(["config", "show"]) == 0
    (line,) = [line for line in capsys.readouterr().out.splitlines() if line.startswith("obs_len =")]
    assert "observed steps the simulator keeps for the predictors: at least each predictor's own" in line


def test_file_problems_are_one_line(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["--config", "nope.toml", "simulate", "--controller", "orca"]) == 2
    assert _one_error_line(capsys, "simulate") == "--config nope.toml: no such file"
    (tmp_path / "bin.toml").write_bytes(b"\xff\xfe[mpc]\n")
    assert main(["--config", "bin.toml", "simulate", "--controller", "orca"]) == 2
    assert _one_error_line(capsys, "simulate") == "bin.toml: not UTF-8 text (a TOML file)"
    _write(tmp_path, "", "a.toml"), _write(tmp_path, "", "b.toml")
    assert main(["--config", "a.toml", "simulate", "--config", "b.toml", "--controller", "orca"]) == 2
    assert "--config given twice" in _one_error_line(capsys, "simulate")


def test_an_unknown_controller_in_a_file_is_one_line(tmp_path, capsys):
    path = _write(tmp_path, '[controller]\ncontroller = "bogus"\n')
    assert main(["simulate", "--config", str(path), "--no-progress"]) == 2
    assert _one_error_line(capsys, "simulate").startswith(
        f"{path}: controller.controller: unknown controller 'bogus'; choose from ['cmpc', 'dmpc', 'orca', "
    )


def test_a_missing_controller_is_the_parsers_error(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["simulate", "--no-progress"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--controller (or [controller] controller)" in err


def test_errors_from_the_python_api_are_config_errors(tmp_path):
    with pytest.raises(ConfigError, match=r"^--set mpc.horizon: must be an integer >= 1, got 0$"):
        load(None, ["mpc.horizon=0"])


# ----------------------------------------------------------------------------------------------------------
# Numbers are checked before any work (issue 15's `--humans 100`)
# ----------------------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "options, message",
    [
        (["--humans", "100"], "--humans: n_humans must be in [0, 50], got 100"),
        (["--humans", "-1"], "--humans: n_humans must be in [0, 50], got -1"),
        (["--robots", "13"], "--robots must be in 1..12, got 13"),
        (["--episodes", "0"], "--episodes must be >= 1, got 0"),
        (["--seed", "-2"], "--seed must be >= 0, got -2"),
        # written into the run's TOML config, whose integers other readers take as 64-bit signed
        (["--seed", str(2**63)], f"--seed must be at most 2**63 - 1 (TOML's largest integer), got {2**63}"),
        (  # its last episode ran at 2**63 and was recorded under a seed --seed then refused
            ["--seed", str(2**63 - 1), "--episodes", "2"],
            f"--seed must be at most {2**63 - 2} with 2 episodes (its last episode's seed, seed + 1, "
            f"must stay within 2**63 - 1, TOML's largest integer), got {2**63 - 1}",
        ),
        (["--set", "scenario.humans=100"], "--set scenario.humans: n_humans must be in [0, 50], got 100"),
        (["--set", "mpc.horizon=100000"], "--set mpc.horizon: must be at most 100, got 100000"),
        (["--set", "mpc.j_max=1e9"], "--set mpc.j_max: must be an integer >= 1, got 1000000000.0"),
        (["--set", "env.time_limit=1e9"], "--set env.time_limit: must be at most 86400.0, got 1000000000.0"),
        # an Inf Hessian: a Fatrop solve ran past time_limit_s for minutes
        (["--set", "mpc.rho=1e300"], "--set mpc.rho: must be at most 1000 s^2, got 1e+300"),
        (
            ["--set", "env.orca.neighbor_dist=1e300"],  # squared: OverflowError in the first ORCA step
            "--set env.orca.neighbor_dist: must be a number > 0 and at most 1e+06 m, or inf (every agent), "
            "got 1e+300",
        ),
        (
            ["--set", "env.orca.max_neighbors=100000"],
            "--set env.orca.max_neighbors: must be at most 1000, got 100000",
        ),  # fmt: skip
        (
            ["--set", "world.dt=1e-6"],
            "--set world.dt: env.time_limit (unset: the paper profile's 40.0): must be at most 100000 steps "
            "of dt = 1e-06 s, got 40 s (3.9e+07 steps)",
        ),
    ],
)
def test_simulate_numbers_are_refused_before_any_episode(options, message, capsys, monkeypatch):
    def no_episodes(*args, **kwargs):
        raise AssertionError("episodes started")

    monkeypatch.setattr("pipelines.loop.episode.run_episodes", no_episodes)
    monkeypatch.setattr("pipelines.loop.episode.make_controller", no_episodes)
    assert main(["simulate", "--controller", "cmpc", *options]) == 2  # progress bar on: none may start
    assert _one_error_line(capsys, "simulate") == message


# ----------------------------------------------------------------------------------------------------------
# The effective config in simulate's JSON and MCAP metadata
# ----------------------------------------------------------------------------------------------------------


def test_simulate_records_the_effective_config_in_json_and_mcap(tmp_path, capsys):
    from pipelines.logs.reader import read_recording

    path = _write(
        tmp_path, '[controller]\ncontroller = "straight"\n[scenario]\nhumans = 2\n[env]\ntime_limit = 20\n'
    )
    out, rec = tmp_path / "run.json", tmp_path / "rec"
    argv = ["--config", str(path), "--set", "env.orca.max_neighbors=5", "simulate", "--json", str(out)]
    argv += ["--record", str(rec), "--no-progress"]
    assert main(argv) == 0
    run = json.loads(out.read_text())["run"]
    assert run["config_file"] == str(path)
    config = run["config"]
    assert config["env"]["time_limit"] == 20.0 and config["env"]["timeout_margin"] == 1.0  # the profile's
    assert config["env.orca"]["max_neighbors"] == 5 and config["scenario"]["humans"] == 2
    assert set(config) == {"world", "env", "env.orca", "scenario", "controller", "mpc", "simulate", "sweep"}
    (mcap,) = sorted(rec.glob("*.mcap"))
    meta = read_recording(mcap).metadata
    recorded = meta["run"]["config"]
    recorded = json.loads(recorded) if isinstance(recorded, str) else recorded
    assert recorded == config
    env = meta["config"]["env"]
    env = json.loads(env) if isinstance(env, str) else env
    assert env["time_limit"] == 20.0  # what the simulator ran with


# ----------------------------------------------------------------------------------------------------------
# docs/examples/demo.toml is `make demo`
# ----------------------------------------------------------------------------------------------------------


def _make_demo_argv() -> list[str]:
    """The arguments of `crowdmpc` in the Makefile's demo recipe."""
    lines = (REPO / "Makefile").read_text().splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("demo:"))
    recipe = ""
    for line in lines[start + 1 :]:
        if not line.startswith("\t"):
            break
        recipe += line.strip().removesuffix("\\") + " "
    words = shlex.split(recipe)
    return words[next(i for i, w in enumerate(words) if w.endswith("crowdmpc")) + 1 :]


def _resolved(argv: list[str]):
    from pipelines.cli import build_parser
    from pipelines.commands.simulate import resolve_run

    run = resolve_run(build_parser().parse_args(argv))
    return run.spec, _objects(run.config), (run.json, run.plot, run.record)


def test_demo_toml_resolves_to_make_demos_run(monkeypatch):
    monkeypatch.chdir(REPO)  # where `make demo` runs; the paths are relative to it
    demo = _make_demo_argv()
    assert demo[0] == "simulate" and "--controller" in demo
    assert _resolved(demo) == _resolved(["--config", str(DEMO_TOML.relative_to(REPO)), "simulate"])


def test_safe_crossing_toml_is_the_readmes_command_line(monkeypatch):
    """docs/examples/safe_crossing.toml sets the margins, the guidance, the stall release and DMPC's update
    that docs/safe_crossing.md's tables were run with, and nothing else."""
    monkeypatch.chdir(REPO)
    sets = [
        "mpc.guidance=standing",
        "mpc.guidance_clearance=penalty",
        "mpc.stall_release_s=4",
        "mpc.dmpc_update=gauss_seidel",
        "mpc.dmpc_stop=no_improvement",
    ]
    cli = ["simulate", "--controller", "dmpc", "--predictor", "social_lstm_eth"]
    cli += ["--margins", "conformal-shortfall:0.05", *(w for s in sets for w in ("--set", s))]
    toml = ["--config", "docs/examples/safe_crossing.toml", "simulate", "--controller", "dmpc"]
    toml += ["--predictor", "social_lstm_eth"]
    assert _resolved(toml) == _resolved(cli)
    spec = _resolved(toml)[0]
    assert dict(spec.mpc_overrides) == {
        "guidance": "standing",
        "guidance_clearance": "penalty",
        "stall_release_s": 4.0,
        "dmpc_update": "gauss_seidel",
        "dmpc_stop": "no_improvement",
    }


def test_many_robots_toml_is_the_safe_crossing_plus_what_a_larger_flock_needs(monkeypatch):
    """docs/examples/many_robots.toml: safe_crossing.toml's settings, flocking weighed per robot, parked
    robots that yield, F / 100 for the solver and DMPC's heading start, what docs/results.md's robot-scaling
    rows were run with, and nothing else."""
    monkeypatch.chdir(REPO)
    safe = _resolved(["--config", "docs/examples/safe_crossing.toml", "simulate", "--controller", "cmpc"])[0]
    many = _resolved(["--config", "docs/examples/many_robots.toml", "simulate", "--controller", "cmpc"])[0]
    assert many.margins == safe.margins
    more = {"on_goal": "yield", "cost_scale": 0.01, "dmpc_start": "heading", "flocking_weight": "per_robot"}
    assert dict(many.mpc_overrides) == dict(safe.mpc_overrides) | more


def _without_wall_clock(record: dict) -> dict:
    solver = {k: v for k, v in record["solver"].items() if not k.endswith("_ms")}
    return {**record, "solver": solver}


def test_demo_toml_gives_make_demos_metrics(tmp_path, capsys):
    demo = _make_demo_argv()
    # outputs go to tmp_path: the command line's --record and --plot take precedence over the file's
    outputs = {"--record": str(tmp_path / "cli"), "--plot": str(tmp_path / "cli.png")}
    cli = [outputs.get(prev, word) for prev, word in zip(["", *demo[:-1]], demo, strict=True)]
    assert main([*cli, "--json", str(tmp_path / "cli.json"), "--no-progress"]) == 0
    argv = ["--config", str(DEMO_TOML), "simulate", "--json", str(tmp_path / "toml.json"), "--no-progress"]
    argv += ["--record", str(tmp_path / "toml"), "--plot", str(tmp_path / "toml.png")]
    assert main(argv) == 0
    capsys.readouterr()
    by_cli, by_toml = (json.loads((tmp_path / f"{n}.json").read_text()) for n in ("cli", "toml"))
    assert [_without_wall_clock(r) for r in by_toml["episodes"]] == [
        _without_wall_clock(r) for r in by_cli["episodes"]
    ]
    assert by_toml["run"]["config"]["controller"] == by_cli["run"]["config"]["controller"]
    assert by_toml["run"]["config"]["mpc"] == by_cli["run"]["config"]["mpc"]
    assert len(list((tmp_path / "toml").glob("*.mcap"))) == 1


# ----------------------------------------------------------------------------------------------------------
# Sweeps: the config's experiment settings, its choices applied to every method, and the records
# ----------------------------------------------------------------------------------------------------------


def test_a_sweep_from_a_config_file_records_its_effective_config(tmp_path, capsys):
    out = tmp_path / "sweep"
    path = _write(
        tmp_path,
        f'[sweep]\nexperiment = "baselines"\nout = "{out}"\nhumans = [2]\nepisodes_per_cell = 2\n'
        'backend = "inline"\n[scenario]\nrobots = 2\n',
    )
    assert main(["--config", str(path), "sweep", "--no-progress"]) == 0
    capsys.readouterr()
    records = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    assert len(records) == 4 and all(r["n_robots"] == 2 for r in records)
    for record in records:
        assert record["config"]["env"]["time_limit"] == 40.0  # the cell's simulator, as in MCAP metadata
    run = json.loads((out / "sweep.json").read_text())["runs"][-1]
    assert run["config"]["config_file"] == str(path)
    assert run["config"]["sweep"]["humans"] == [2] and run["config"]["scenario"]["robots"] == 2


def test_records_without_a_config_still_load_and_resume(tmp_path, capsys):
    out = tmp_path / "sweep"
    args = ["sweep", "--experiment", "baselines", "--humans", "2", "--backend", "inline", "--no-progress"]
    assert main([*args, "--episodes-per-cell", "2", "--out", str(out)]) == 0
    log = out / "episodes.jsonl"
    old = [json.loads(line) for line in log.read_text().splitlines()]
    for record in old:  # as written before records carried their config
        record.pop("config")
    log.write_text("".join(json.dumps(r) + "\n" for r in old))
    capsys.readouterr()
    assert main([*args, "--episodes-per-cell", "3", "--out", str(out)]) == 0
    assert "6/6 episodes recorded (2 this run" in capsys.readouterr().err
    records = [json.loads(line) for line in log.read_text().splitlines()]
    assert [("config" in r) for r in records] == [False] * 4 + [True] * 2


def test_a_sweep_applies_mpc_values_to_every_method_as_part_of_the_cell(tmp_path, capsys):
    argv = ["sweep", "--experiment", "table2", "--humans", "5", "--dry-run", "--out", str(tmp_path / "out")]
    assert main([*argv, "--set", "mpc.w_coll=1e6", "--set", "mpc.horizon=4"]) == 0
    out = capsys.readouterr().out
    assert "cmpc-social_lstm_eth-F-ibr-w_coll=1000000.0-m=none-paper-visible-h5-r3" in out
    assert "dmpc-social_lstm_eth-F-ibr-w_coll=1000000.0-m=none-paper-visible-h5-r3" in out
    # w_floc = 0 in an experiment that does not compare flocking: every cell takes it
    assert main([*argv, "--set", "mpc.w_floc=0"]) == 0
    assert "cmpc-social_lstm_eth-F-ibr-w_floc=0.0-m=none-paper-visible-h5-r3" in capsys.readouterr().out
    # a file of defaults (what `config show` writes) changes no cell
    main(["config", "show"])
    defaults = _write(tmp_path, capsys.readouterr().out, "defaults.toml")
    assert main([*argv, "--config", str(defaults)]) == 0
    assert "cmpc-social_lstm_eth-F-ibr-m=none-paper-visible-h5-r3" in capsys.readouterr().out


@pytest.mark.parametrize(
    "experiment, item, message",
    [
        (
            "table3",
            "controller.flocking=false",
            "--set controller.flocking: experiment 'table3' compares its methods' flocking",
        ),  # fmt: skip
        (  # the default, named on purpose, as --no-flocking's opposite would be: once silently dropped
            "table3",
            "controller.flocking=true",
            "--set controller.flocking: experiment 'table3' compares its methods' flocking",
        ),  # fmt: skip
        (
            "coupling",
            "mpc.coupled_mode=exact",
            "--set mpc.coupled_mode: method 'NLP first-order' of experiment 'coupling' sets coupled_mode",
        ),  # fmt: skip
        (  # ORCA and the straight line have no MPC: their cell keys took horizon=8, their episodes did not
            "baselines",
            "mpc.horizon=8",
            "--set mpc.horizon: the methods of experiment 'baselines' ('straight', 'ORCA') plan with no "
            "predictor; [mpc] horizon applies to the controllers that do (cmpc, dmpc)",
        ),  # fmt: skip
        (
            "baselines",
            "controller.flocking=false",
            "--set controller.flocking: the methods of experiment 'baselines' ('straight', 'ORCA') plan with",
        ),  # fmt: skip
        (
            "table2",
            "world.radius=0.2",
            "--set world.radius: 0.2: a sweep's cells share Table I's world facts (time step, history, "
            "radius, bounds), which the controllers and predictors are built for; [world] values apply to "
            "simulate only",
        ),  # fmt: skip
        (  # a cell's humans and episodes: checked as simulate checks them, each profile's with its own
            "conventions",
            'env.goal_assignment="slots"',
            "simulator settings {'goal_assignment': 'slots'}: EnvConfig.goal_assignment 'slots' needs "
            "success_rule 'simultaneous'",
        ),  # fmt: skip
        (  # ignored: the cells ran at the sweep's crowd sizes
            "table2",
            "scenario.humans=9",
            "--set scenario.humans: 9: [scenario] humans applies to simulate only; a sweep's crowd sizes are "
            "--humans",
        ),  # fmt: skip
        (
            "table2",
            "scenario.name=perpendicular",
            "--set scenario.name: 'perpendicular': [scenario] name applies to simulate only; a sweep's "
            "episodes alternate",
        ),  # fmt: skip
        ("table2", "mpc.jit=true", "--set mpc.jit: a sweep compiles by [sweep] jit"),
        (  # its columns are sensor ranges
            "sensing",
            "simulate.sensor_range=3",
            "--set simulate.sensor_range: experiment 'sensing' compares sensor ranges across its methods; "
            "[simulate] sensor_range and sensor_tracks do not apply",
        ),  # fmt: skip
        (
            "table2",
            "simulate.sensor_tracks=false",
            "--set simulate.sensor_tracks: track lengths are a sensor's; give --sensor-range M too",
        ),
        (
            "table3",
            "mpc.w_floc=0",
            "--set mpc.w_floc: experiment 'table3' compares flocking on and off; w_floc = 0 turns it off",
        ),  # fmt: skip
        (
            "baselines",
            "controller.predictor=constant_velocity",
            "--set controller.predictor: experiment 'baselines' fixes each method's predictor",
        ),  # fmt: skip
        ("table2", "sweep.episodes_per_cell=0", "--set sweep.episodes_per_cell: must be at least 1, got 0"),
        ("table2", "sweep.workers=0", "--set sweep.workers: must be at least 1 and at most 4096, got 0"),
    ],
)
def test_a_sweep_refuses_what_it_cannot_apply_in_one_line(experiment, item, message, tmp_path, capsys):
    out = tmp_path / "sweep"
    argv = [
        "sweep",
        "--experiment",
        experiment,
        "--humans",
        "7",
        "--dry-run",
        "--out",
        str(out),
        "--set",
        item,
    ]
    assert main(argv) == 2
    assert _one_error_line(capsys, "sweep").startswith(message)
    assert not out.exists()


def test_a_sweep_refuses_a_files_scenario_humans_and_takes_its_default(tmp_path, capsys):
    """A simulate config's [scenario] humans = 9 ran a sweep at the experiment's crowd sizes without a word;
    the default (what `config show` writes) chooses nothing."""
    argv = ["sweep", "--experiment", "table2", "--dry-run", "--out", str(tmp_path / "sweep")]
    config = _write(tmp_path, "[scenario]\nhumans = 9\n")
    assert main(["--config", str(config), *argv]) == 2
    assert _one_error_line(capsys, "sweep").endswith(
        f"{config}: scenario.humans: 9: [scenario] humans applies to simulate only; a sweep's crowd sizes "
        "are --humans ([sweep] humans)"
    )
    assert main(["--config", str(_write(tmp_path, "[scenario]\nhumans = 7\n")), *argv]) == 0


def test_a_sweep_needs_an_experiment_and_a_directory(tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["sweep", "--out", str(tmp_path)])
    assert "--experiment (or [sweep] experiment)" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["sweep", "--set", "sweep.experiment=baselines"])
    assert "--out (or [sweep] out)" in capsys.readouterr().err


def test_commands_that_read_no_config_refuse_one(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--config", "run.toml", "zoo", "list"])
    assert exc.value.code == 2
    assert capsys.readouterr().err == (
        "crowdmpc: error: --config and --set apply to simulate, sweep and config, not zoo; "
        "see 'crowdmpc --help'\n"
    )


def test_goal_slots_show_in_the_summary_and_the_run_record(tmp_path, capsys):
    out = tmp_path / "run.json"
    argv = ["--set", "env.goal_assignment=slots", "simulate", "--controller", "orca", "--no-progress"]
    assert main([*argv, "--json", str(out)]) == 0
    assert "| paper/visible | goals slots | scenario circle |" in capsys.readouterr().out
    assert json.loads(out.read_text())["run"]["goals"] == "slots"
    assert main(["simulate", "--controller", "orca", "--no-progress"]) == 0
    assert "goals" not in capsys.readouterr().out.splitlines()[0]  # the paper's task: no mention


def test_a_sweeps_mpc_values_apply_to_the_methods_that_plan_with_a_predictor(tmp_path, capsys):
    """--set mpc.horizon=8 and controller.flocking=false went into every cell key of the controllers
    experiment, ORCA's and the straight line's too, though those two ran as before."""
    argv = ["--set", "mpc.horizon=8", "--set", "controller.flocking=false", "sweep", "--experiment"]
    argv += ["controllers", "--humans", "5", "--dry-run", "--out", str(tmp_path / "sweep")]
    assert main(argv) == 0
    keys = {
        line.split()[0]: line.split()[-1]
        for line in capsys.readouterr().out.splitlines()
        if " humans " in line
    }
    assert keys["cmpc"].startswith("cmpc-social_lstm_eth-NF-ibr-horizon=8-")
    assert keys["dmpc"].startswith("dmpc-social_lstm_eth-NF-ibr-horizon=8-")
    assert keys["orca"] == "orca-none-F-ibr-m=none-paper-visible-h5-r3"
    assert keys["straight"] == "straight-none-F-ibr-m=none-paper-visible-h5-r3"


def test_a_sweep_applies_a_files_profile_convention_to_every_cell_and_takes_config_shows_file(
    tmp_path, capsys
):
    """`[env] time_limit = 40.0` in a file, the paper profile's own value, was taken as no choice, and
    conventions' v1 cells ran v1's 30 s; `config show` leaves such keys unset: a file that sets one asks, and
    every cell, v1's too, runs it, v1's keys naming it (the paper's cells are Table II's: their profile's own
    value adds nothing to them)."""
    argv = [
        "sweep",
        "--experiment",
        "conventions",
        "--humans",
        "5",
        "--dry-run",
        "--out",
        str(tmp_path / "sw"),
    ]
    config = _write(tmp_path, "[env]\ntime_limit = 40.0\n")
    assert main(["--config", str(config), *argv]) == 0
    keys = [line.split()[-1] for line in capsys.readouterr().out.splitlines() if " humans " in line]
    assert len(keys) == 8 and sum("-v1-" in key for key in keys) == 4
    assert all(key.endswith("-time_limit=40.0-h5-r3") == ("-v1-" in key) for key in keys)
    assert main(["config", "show"]) == 0
    shown = _write(tmp_path, capsys.readouterr().out)
    assert main(["--config", str(shown), *argv]) == 0
    keys = [line.split()[-1] for line in capsys.readouterr().out.splitlines() if " humans " in line]
    assert len(keys) == 8 and not any("time_limit" in key for key in keys)


@pytest.mark.parametrize(
    "arguments, message",
    [
        ((123,), "the config file must be a path, got 123"),
        ((None, "mpc.horizon=3"), "sets must be a list of 'SECTION.KEY=VALUE' strings, got 'mpc.horizon=3'"),
        ((None, None), "sets must be a list of 'SECTION.KEY=VALUE' strings, got None"),
        ((None, [3]), "sets must be a list of 'SECTION.KEY=VALUE' strings, got [3]"),
    ],
)
def test_load_from_python_names_arguments_of_the_wrong_kind(arguments, message):
    """A string of sets was read letter by letter ("--set 'm': expected SECTION.KEY=VALUE"); the others
    failed in pathlib or iteration with Python's TypeError."""
    with pytest.raises(ConfigError, match=f"^{re.escape(message)}$"):
        load(*arguments)
    assert load(None, ["mpc.horizon=3"]).mpc.horizon == 3


def test_a_sweeps_vary_is_taken_bare_by_set_as_by_vary(capsys):
    """`--set sweep.vary=mpc.d_min=0.8,0.9` was "not a TOML value" where `--vary mpc.d_min=0.8,0.9` and
    `--set controller.margins=fixed:0.1,0.1` are taken bare: "=" and ";" are a vary's own characters."""
    from pipelines.config.entries import parse_set

    assert parse_set("sweep.vary=mpc.d_min=0.8,0.9").value == "mpc.d_min=0.8,0.9"
    assert parse_set("sweep.vary=mpc.d_min=0.8,0.9;mpc.w_coll=1e6,1e7").value == (
        "mpc.d_min=0.8,0.9;mpc.w_coll=1e6,1e7"
    )
    assert parse_set('sweep.vary="mpc.d_min=0.8,0.9"').value == "mpc.d_min=0.8,0.9"  # quoted, as before
