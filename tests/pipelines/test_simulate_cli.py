"""``crowdmpc simulate`` end to end with the baselines."""

import json

import pytest

from pipelines.cli import main


def test_simulate_orca_prints_the_table_and_writes_json_and_plot(tmp_path, capsys):
    out_json, out_png = tmp_path / "run.json", tmp_path / "ep.png"
    code = main(
        ["simulate", "--controller", "orca", "--scenario", "circle", "--humans", "5", "--episodes", "2",
         "--seed", "7", "--json", str(out_json), "--plot", str(out_png), "--no-progress"]
    )  # fmt: skip
    assert code == 0
    text = capsys.readouterr().out
    for row in ("success", "travel time", "collision", "contact", "discomfort", "min distance", "solve time",
                "IBR iterations", "collision between steps", "contact between steps"):  # fmt: skip
        assert row in text
    payload = json.loads(out_json.read_text())
    assert payload["summary"]["episodes"] == 2
    summary = payload["summary"]
    assert summary["collision_between_steps_count"] >= summary["collision_count"]  # never fewer
    for episode in payload["episodes"]:
        m = episode["metrics"]
        assert m["min_distance_between_steps"] <= m["min_distance"]
    assert [e["seed"] for e in payload["episodes"]] == [7, 8]
    assert payload["run"]["controller"] == "orca" and payload["run"]["predictor"] is None
    assert out_png.read_bytes()[:4] == b"\x89PNG"


def test_simulate_records_one_mcap_per_episode(tmp_path, capsys):
    pytest.importorskip("pipelines.logs.recording")
    code = main(
        ["simulate", "--controller", "straight", "--humans", "3", "--episodes", "2", "--record",
         str(tmp_path / "rec"), "--no-progress"]
    )  # fmt: skip
    assert code == 0
    assert sorted(p.name for p in (tmp_path / "rec").glob("*.mcap")) == [
        "circle_seed000000.mcap",
        "circle_seed000001.mcap",
    ]


def test_each_json_episode_keeps_the_config_it_ran_with_as_its_recording_and_a_sweep_line_do(tmp_path):
    """--json kept the margins as the option's text ("conformal:0.1"), not the metres the MPC planned with,
    which come from the zoo's calibrations and change when it is recalibrated; the recording's "config"
    metadata and a sweep line's "config" had them. Each episode now carries that same "config"."""
    from mcap.reader import make_reader

    out_json, rec = tmp_path / "run.json", tmp_path / "rec"
    code = main(
        ["simulate", "--controller", "cmpc", "--predictor", "constant_velocity", "--humans", "2",
         "--margins", "fixed:0.1,0.2,0.3,0.4", "--json", str(out_json), "--record", str(rec), "--no-progress"]
    )  # fmt: skip
    assert code == 0
    (episode,) = json.loads(out_json.read_text())["episodes"]
    assert episode["config"]["margins"]["margins_m"] == [0.1, 0.2, 0.3, 0.4]
    with open(rec / "circle_seed000000.mcap", "rb") as f:
        recorded = {m.name: m.metadata for m in make_reader(f).iter_metadata()}["config"]
    assert episode["config"] == {key: json.loads(value) for key, value in recorded.items()}


@pytest.mark.parametrize(
    "args, message",
    [
        (["--episodes", "0"], "--episodes must be >= 1, got 0"),
        (["--episodes", "1000000"], "--episodes must be at most 100000"),
        (["--robots", "13"], "--robots must be in 1..12, got 13"),
        (["--humans", "60"], "n_humans must be in [0, 50], got 60"),
        (["--plot", "episode.foo"], "--plot episode.foo: cannot write a figure of type 'foo'"),
    ],
)
def test_bad_options_are_one_line_errors(args, message, capsys):
    assert main(["simulate", "--controller", "orca", "--no-progress", *args]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_unknown_scenario_is_rejected_by_the_parser(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["simulate", "--controller", "orca", "--scenario", "square"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert "argument --scenario: invalid choice: 'square' (choose from 'circle', 'perpendicular')" in err


def test_the_coupling_help_says_what_its_choices_are(capsys):
    """`--coupling {ibr,nlp}` read "default: ibr": neither word is expanded in simulate's help, nor "IBR"
    anywhere a newcomer reads before the summary's "IBR iterations" row."""
    with pytest.raises(SystemExit):
        main(["simulate", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    coupling = text.split("--coupling {ibr,nlp,none} ")[1].split(" --margins")[0]
    assert (
        "iterative best response" in coupling and "predictor inside" in coupling and "cmpc only" in coupling
    )
    assert "none: predict, then plan, the predictor blind to the robots" in coupling


def test_an_unknown_predictor_lists_the_zoo_and_the_oracle(capsys):
    assert main(["simulate", "--controller", "cmpc", "--predictor", "nope", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "unknown predictor 'nope'" in err and "'constant_velocity'" in err and "'orca_oracle'" in err


def test_a_run_without_humans_prints_no_distance_where_the_json_has_none(tmp_path, capsys):
    """With no humans the robot-human distance is inf (no pair): the table printed "inf m" where the JSON
    and review say null / "-"."""
    out = tmp_path / "h0.json"
    argv = ["simulate", "--controller", "straight", "--humans", "0", "--no-progress", "--json", str(out)]
    assert main(argv) == 0
    line = next(l for l in capsys.readouterr().out.splitlines() if l.strip().startswith("min distance"))
    assert "inf" not in line and "n/a" in line
    assert json.loads(out.read_text())["summary"]["min_distance_min"] is None


def test_the_plots_title_names_the_run_and_what_happened(tmp_path, capsys, monkeypatch):
    """The --plot title read "cmpc, circle, seed 0: success in 10.4 s, min robot-human distance inf m"
    without humans, and "straight, circle, seed 0: success in 10.4 s, min robot-human distance 0.51 m" for
    a straight run through a human (contact, which the table counts); neither predictor nor crowd named."""
    import crowdsim.plotting

    titles = []
    draw = crowdsim.plotting.plot_episode

    def spy(*args, **kwargs):
        titles.append(kwargs["title"])
        return draw(*args, **kwargs)

    monkeypatch.setattr(crowdsim.plotting, "plot_episode", spy)
    for argv in (["cmpc", "--robots", "1", "--humans", "0"], ["straight", "--robots", "3", "--humans", "7"]):
        plot = ["--plot", str(tmp_path / "ep.png"), "--no-progress", "--seed", "0"]
        assert main(["simulate", "--controller", *argv, *plot]) == 0
    capsys.readouterr()
    assert titles == [
        "cmpc with constant_velocity, circle, 1 robot, 0 humans, seed 0\nsuccess in 10.4 s, no humans",
        "straight, circle, 3 robots, 7 humans, seed 0\n"
        "success in 10.4 s, min robot-human distance 0.51 m: contact",
    ]


def test_the_plots_title_counts_one_human_in_the_singular(tmp_path, capsys, monkeypatch):
    import crowdsim.plotting

    titles = []
    draw = crowdsim.plotting.plot_episode
    monkeypatch.setattr(
        crowdsim.plotting, "plot_episode", lambda *a, **k: titles.append(k["title"]) or draw(*a, **k)
    )
    plot = ["--plot", str(tmp_path / "ep.png"), "--no-progress", "--seed", "0"]
    assert main(["simulate", "--controller", "straight", "--robots", "1", "--humans", "1", *plot]) == 0
    capsys.readouterr()
    assert titles[0].startswith("straight, circle, 1 robot, 1 human, seed 0\n")  # said "1 humans"


def test_steps_whose_prediction_was_nan_are_printed():
    """A plugin predictor returning NaN when two agents come close made CMPC fall back on 110 of 145 steps
    (status "nan_prediction"): the JSON's statuses held it, the printed table said only "fallback steps 110
    of 145", and its metrics read as the predictor's. A run without such steps prints no such row."""
    from pipelines.commands.simulate_table import format_table
    from pipelines.loop.controllers import ControllerSpec
    from pipelines.loop.episode import run_episodes, summarize

    summary = summarize(run_episodes(ControllerSpec("straight"), episodes=1, seed=0, scenario="circle",
                                     n_humans=2, progress=False))  # fmt: skip
    assert "NaN predictions" not in format_table(summary, "header")
    summary["statuses"], summary["control_steps"] = {"ok": 35, "nan_prediction": 110}, 145
    assert (
        "NaN predictions          110 of 145 steps stopped at a NaN or inf prediction (a step with no solved "
        "iteration before it fell back)" in format_table(summary, "header")
    )


def test_the_nan_row_does_not_say_every_such_step_fell_back():
    """A step whose prediction turned NaN after an iteration had solved keeps that iteration's plan: status
    "nan_prediction", no fallback. The row said "N of M steps fell back" for all of them, beside a "fallback
    steps" row that (rightly) did not count them."""
    import numpy as np

    from mpc.cmpc import CMPC
    from mpc.config import MPCConfig
    from mpc.fallback import PlanMemory
    from pipelines.commands.simulate_table import format_table
    from pipelines.loop.controllers import ControllerSpec
    from pipelines.loop.episode import run_episodes, summarize
    from tests.mpc.test_fallback import moving_data

    cfg, data, calls = MPCConfig(), moving_data(), []

    def finite_then_nan(robots_future):  # the first IBR iteration's prediction finite, the next NaN
        calls.append(robots_future)
        value = 0.01 * robots_future.mean() if len(calls) == 1 else np.nan
        return np.full((cfg.horizon, 1, 2), value) + [5.0, -5.0]

    result = CMPC(cfg, 2, 1).solve(data, finite_then_nan, PlanMemory(cfg).start(data))
    assert result.status == "nan_prediction" and result.solved  # kept the solved plan: no fallback
    summary = summarize(run_episodes(ControllerSpec("straight"), episodes=1, seed=0, scenario="circle",
                                     n_humans=2, progress=False))  # fmt: skip
    summary["statuses"] = {"ok": summary["control_steps"] - 1, "nan_prediction": 1}
    summary["fallback_steps"] = 0
    row = next(line for line in format_table(summary, "h").splitlines() if "NaN" in line)
    assert "fell back:" not in row and "steps fell back" not in row


SWAP = "tests.plugins.toy_controller:SwapGoals"  # two robots heading for each other's goal cross halfway


def test_the_summary_shows_robot_robot_contact(tmp_path, capsys, monkeypatch):
    """Two robots that touched each other were counted as nothing: the metrics were all robot-human, and an
    episode of robots passing 0.24 m apart read as a clean success. The row is not one of the paper's."""
    from pipelines.loop import spec as registry

    monkeypatch.setattr(registry, "_PLUGINS", {})
    monkeypatch.delenv(registry.PLUGINS_ENV, raising=False)
    out = tmp_path / "swap.json"
    argv = ["--plugin", SWAP, "simulate", "--controller", SWAP, "--humans", "0", "--robots", "2",
            "--episodes", "1", "--no-progress", "--json", str(out)]  # fmt: skip
    assert main(argv) == 0
    lines = capsys.readouterr().out.splitlines()
    (row,) = [line for line in lines if "robot-robot contact" in line]
    m = json.loads(out.read_text())["episodes"][0]["metrics"]
    assert m["robot_contact"] and m["robot_contact_steps"] > 0 and m["min_distance_robots"] < 0.6
    states = m["n_steps"] + 1  # the row's frequency: the touching states of all states
    assert row.split() == ["robot-robot", "contact", "100.0", "%", "(1/1),",
                           f"{100 * m['robot_contact_steps'] / states:.2f}", "%", "of", "states,", "between",
                           "steps", "100.0", "%", "(1/1):", "two", "robots", "closer", "than", "0.6", "m",
                           "(not", "in", "the", "paper)"]  # fmt: skip
    assert m["robot_contact_between_steps"]
    assert m["min_distance_robots_between_steps"] <= m["min_distance_robots"]
    summary = json.loads(out.read_text())["summary"]
    assert (summary["robot_contact_count"], summary["robot_contact_rate"]) == (1, 100.0)
    assert (summary["contact_count"], summary["success_count"]) == (0, 0)  # no human; none at its own goal


def test_the_plots_title_says_when_robots_touched(tmp_path, capsys, monkeypatch):
    """Two robots crossing 0.24 m apart read "success ..., no humans" on the figure, as a clean run."""
    import crowdsim.plotting
    from pipelines.loop import spec as registry

    monkeypatch.setattr(registry, "_PLUGINS", {})
    monkeypatch.delenv(registry.PLUGINS_ENV, raising=False)
    titles = []
    draw = crowdsim.plotting.plot_episode
    monkeypatch.setattr(
        crowdsim.plotting, "plot_episode", lambda *a, **k: titles.append(k["title"]) or draw(*a, **k)
    )
    out, png = tmp_path / "swap.json", tmp_path / "swap.png"
    argv = ["--plugin", SWAP, "simulate", "--controller", SWAP, "--humans", "0", "--robots", "2",
            "--episodes", "1", "--no-progress", "--json", str(out), "--plot", str(png)]  # fmt: skip
    assert main(argv) == 0
    capsys.readouterr()
    m = json.loads(out.read_text())["episodes"][0]["metrics"]
    closest = m["min_distance_robots_between_steps"]
    assert closest < m["min_distance_robots"] < 0.6  # the crossing falls between two recorded states
    (title,) = titles
    assert title.endswith(f"no humans; robots touched ({closest:.2f} m apart)")


def test_the_robot_contact_row_reads_n_a_for_older_records():
    """A summary over records from before the field (aggregate's NaN) prints n/a, not 0 %."""
    from pipelines.commands.simulate_table import format_table
    from pipelines.loop.controllers import ControllerSpec
    from pipelines.loop.episode import run_episodes, summarize

    summary = summarize(run_episodes(ControllerSpec("straight"), episodes=1, seed=0, scenario="circle",
                                     n_humans=0, n_robots=3, progress=False))  # fmt: skip
    (row,) = [line for line in format_table(summary, "h").splitlines() if "robot-robot" in line]
    # 1 m apart, a row of 3
    assert "  0.0 %  (0/1), 0.00 % of states, between steps 0.0 % (0/1): two robots closer than 0.6 m" in row
    summary |= {"robot_contact_rate": float("nan"), "robot_contact_count": float("nan")}
    summary["robot_contact_step_freq"] = float("nan")
    summary |= {f"robot_contact_between_steps_{k}": float("nan") for k in ("rate", "count")}
    (row,) = [line for line in format_table(summary, "h").splitlines() if "robot-robot" in line]
    assert row.split()[2:10] == ["n/a,", "n/a", "of", "states,", "between", "steps", "n/a:", "two"]


def test_a_run_that_mostly_fell_back_says_so():
    """[world] dt = 0.2 left every CMPC solve at its 100 iterations: 195 of 195 steps fell back, the robots
    braked all episode, and the table read "success 0.0 %" as the method's with nothing said; under half of
    the steps falling back, no such row."""
    from pipelines.commands.simulate_table import format_table
    from pipelines.loop.controllers import ControllerSpec
    from pipelines.loop.episode import run_episodes, summarize

    summary = summarize(run_episodes(ControllerSpec("straight"), episodes=1, seed=0, scenario="circle",
                                     n_humans=2, progress=False))  # fmt: skip
    summary["statuses"], summary["control_steps"] = {"ok": 5, "Maximum_Iterations_Exceeded": 190}, 195
    summary["fallback_steps"] = 97
    assert "mostly fallbacks" not in format_table(summary, "h")
    summary["fallback_steps"] = 190
    (row,) = [line for line in format_table(summary, "h").splitlines() if "mostly fallbacks" in line]
    assert (
        "190 of 195 steps fell back (most: Maximum_Iterations_Exceeded)" in row and "solver_max_iter" in row
    )
    # cut by the wall-time budget, where more iterations cannot help: the budget is named
    summary["statuses"] = {"ok": 5, "Maximum_WallTime_Exceeded": 190}
    (row,) = [line for line in format_table(summary, "h").splitlines() if "mostly fallbacks" in line]
    assert "a longer mpc.time_limit_s may let it solve" in row and "solver_max_iter" not in row


@pytest.mark.parametrize("json_arg", ["file", "-"])
def test_a_run_stopped_before_its_first_episode_finished_still_writes_its_json(tmp_path, capsys, json_arg):
    """A plugin's error in episode 0 left an earlier run's --json file in place (a script then read the old
    results as this run's), and `--json -` gave an empty stdout: the document is written, summary null."""
    plugin = "tests.plugins.failing_controllers:RaisesInAct"
    path = tmp_path / "run.json"
    path.write_text('{"old": 1}\n')
    target = str(path) if json_arg == "file" else "-"
    argv = ["--plugin", plugin, "simulate", "--controller", plugin, "--humans", "2", "--episodes", "2"]
    code = main([*argv, "--no-progress", "--json", target])
    out = capsys.readouterr().out
    payload = json.loads(path.read_text() if json_arg == "file" else out)
    assert code != 0 and payload["episodes_finished"] == 0 and payload["summary"] is None
    assert payload["episodes"] == [] and "boom in act" in payload["failed"]["error"]
    assert payload["failed"]["seed"] == 0


def test_simulate_holds_one_trajectory_and_reports_as_if_it_held_all(tmp_path, capsys, monkeypatch):
    """simulate held every episode's trajectories to the end though only --plot's first episode is drawn:
    its memory grew about 4 MB per 100 CMPC episodes. The summary and --json of the slimmed results equal
    those of the whole ones, and one config shared by every episode is held once."""
    from pipelines.commands import simulate
    from pipelines.loop.controllers import ControllerSpec
    from pipelines.loop.episode import run_episodes, summarize
    from pipelines.loop.record import EpisodeConfigs

    configs = EpisodeConfigs()
    whole = run_episodes(ControllerSpec("orca"), episodes=3, seed=4, scenario="circle", n_humans=3,
                         progress=False, observers_factory=lambda: (configs,))  # fmt: skip
    kept = simulate._FirstWhole()
    for result in whole:
        kept.append(result)
    assert kept[0] is whole[0] and kept[1].robot_positions.shape == (0, 3, 2)
    assert kept[2].human_positions.shape == (0, 3, 2) and whole[2].human_positions.shape[0] > 1
    assert summarize(kept) == summarize(whole) and [r.record() for r in kept] == [r.record() for r in whole]
    assert configs.configs[0] is configs.configs[1] is configs.configs[2]
    # and through the command: its --json carries the full records, its plot the first episode
    out_json = tmp_path / "run.json"
    argv = ["simulate", "--controller", "orca", "--humans", "3", "--episodes", "3", "--seed", "4"]
    assert main([*argv, "--json", str(out_json), "--no-progress"]) == 0
    episodes = json.loads(out_json.read_text())["episodes"]
    assert [e["metrics"]["travel_time"] for e in episodes] == [r.metrics.travel_time for r in whole]


def test_the_help_states_the_defaults_its_config_schema_holds(monkeypatch):
    """--scenario, --humans, --robots, --episodes and --seed stated the config's defaults as literals, which a
    change of the schema's default would have left saying the old value: they read it from the schema."""
    import argparse
    import dataclasses

    from pipelines.cli import build_parser
    from pipelines.config import schema

    changed = {
        ("scenario", "name"): "perpendicular",
        ("scenario", "humans"): 5,
        ("scenario", "robots"): 4,
        ("simulate", "episodes"): 3,
        ("simulate", "seed"): 11,
    }
    for name in ("scenario", "simulate"):
        section = schema.SECTION_BY_NAME[name]
        keys = tuple(
            dataclasses.replace(k, default=changed.get((name, k.name), k.default)) for k in section.keys
        )
        monkeypatch.setitem(schema.SECTION_BY_NAME, name, dataclasses.replace(section, keys=keys))
    (commands,) = [a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)]
    helps = {action.dest: action.help for action in commands.choices["simulate"]._actions}
    assert helps["scenario"] == "where the humans start and head (default: perpendicular)"
    assert helps["humans"].endswith("(default: 5)") and helps["robots"].endswith("(default: 4)")
    assert helps["episodes"] == "episodes to run (default: 3)"
    assert helps["seed"] == "first episode's seed (default: 11)"


def test_the_help_states_the_defaults_of_coupling_margins_conventions_and_the_sweeps_seed(monkeypatch):
    """simulate's --predictor, --coupling, --margins, --profile and --visibility, and sweep's --seed, still
    stated their defaults as literals, which a change of the config's default (or of what simulate runs
    when no predictor or margins are chosen) would have left saying the old value."""
    import argparse
    import dataclasses

    from pipelines.cli import build_parser
    from pipelines.config import schema
    from pipelines.loop.controllers import ControllerSpec
    from pipelines.loop.margins import MarginSpec

    def helps(command: str) -> dict[str, str]:
        (commands,) = [a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)]
        return {action.dest: action.help for action in commands.choices[command]._actions}

    paper = helps("simulate")
    changed = {
        ("controller", "coupling"): "nlp",
        ("env", "profile"): "v1",
        ("env", "robots_visible"): False,
        ("sweep", "seed"): 11,
    }
    for name in ("controller", "env", "sweep"):
        section = schema.SECTION_BY_NAME[name]
        keys = tuple(
            dataclasses.replace(k, default=changed.get((name, k.name), k.default)) for k in section.keys
        )
        monkeypatch.setitem(schema.SECTION_BY_NAME, name, dataclasses.replace(section, keys=keys))
    monkeypatch.setattr(ControllerSpec, "predictor", "social_lstm_eth")
    monkeypatch.setattr(ControllerSpec, "margins", MarginSpec(mode="conformal"))
    simulate = helps("simulate")
    assert simulate["predictor"].endswith("(default: social_lstm_eth)")
    assert simulate["coupling"].startswith("ibr: iterative best response")
    assert "; nlp (default): the predictor inside CMPC's joint NLP" in simulate["coupling"]
    assert "none (the paper), conformal[" in simulate["margins"]
    assert simulate["margins"].endswith("fixed:M1,..,MH (metres) (default: conformal)")
    assert simulate["profile"] == "simulation conventions (default: v1)"
    assert simulate["visibility"] == "robots seen by the humans' ORCA (default: invisible)"
    assert helps("sweep")["seed"] == "first crowd's seed (default 11)"
    # at the shipped defaults, the words as they were
    assert paper["coupling"].startswith("ibr (default): iterative best response to the humans' predictions")
    assert "robot-human distance: none (the paper, default), conformal[" in paper["margins"]
    assert paper["margins"].endswith("fixed:M1,..,MH (metres)")
    assert paper["profile"] == "simulation conventions (default: paper)"
    assert paper["visibility"] == "robots seen by the humans' ORCA (default: visible)"
