"""Controllers register like predictor nets: ``crowdmpc --plugin module:Class`` (told apart from a net by what
the class is), ``$CROWDMPC_CONTROLLERS`` and entry points in ``crowdmpc.controllers``; a plugin runs in
``simulate`` and ``run_episode``, and every way to get it wrong is one line."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from importlib.metadata import EntryPoint
from pathlib import Path

import pytest

from pipelines import plugins
from pipelines.cli import main
from pipelines.errors import PipelineError
from pipelines.loop import spec as registry
from pipelines.loop.controllers import (
    ControllerSpec,
    UnknownController,
    controller_names,
    make_controller,
    register_controller_plugins,
)
from pipelines.loop.episode import run_episode
from predictors import models
from predictors.models import PLUGINS_ENV as NETS_ENV
from predictors.models import model_names
from tests.cli_calls import parser_error
from tests.cli_calls import run_cli as run

REPO = Path(__file__).resolve().parents[2]
TOYS = "tests.plugins.toy_controller"
TOY = f"{TOYS}:StraightLine"
NET = "tests.plugins.toy_predictor:ToyNet"
NEVER = "tests.plugins.never_imported:Controller"  # importing that module raises
SHIPPED = ["cmpc", "dmpc", "orca", "straight"]


@pytest.fixture(autouse=True)
def _fresh_registries(monkeypatch, tmp_path_factory):
    """No plugin registered before a test, none left after (the registries are per process)."""
    monkeypatch.setattr(registry, "_PLUGINS", {})
    monkeypatch.setattr(models, "_PLUGINS", {})
    monkeypatch.delenv(registry.PLUGINS_ENV, raising=False)
    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path_factory.mktemp("cache")))


# ---------------------------------------------------------------------------------------------- the flow
def test_simulate_runs_a_plugin_controller(tmp_path, capsys):
    out = tmp_path / "toy.json"
    code, stdout, _ = run(
        capsys, "--plugin", TOY, "simulate", "--controller", TOY, "--humans", "2", "--episodes", "2",
        "--no-progress", "--json", str(out),
    )  # fmt: skip
    assert code == 0 and stdout.startswith(f"controller {TOY} | predictor - |")
    payload = json.loads(out.read_text())
    assert [e["controller"] for e in payload["episodes"]] == ["straight_line", "straight_line"]
    assert all(e["metrics"]["success"] and e["predictor"] is None for e in payload["episodes"])
    assert os.environ[registry.PLUGINS_ENV] == TOY  # for the processes the command starts
    assert NETS_ENV not in os.environ  # a controller is no model kind
    assert TOY in controller_names() and TOY not in model_names()


def test_a_sweep_compares_a_plugin_controller_with_shipped_ones_in_worker_processes(tmp_path, capsys):
    out = tmp_path / "sweep"
    code, stdout, _ = run(
        capsys, "--plugin", TOY, "sweep", "--experiment", "controllers", "--controllers", f"orca,{TOY}",
        "--humans", "3", "--episodes-per-cell", "2", "--workers", "2", "--backend", "process", "--jit", "off",
        "--no-progress", "--out", str(out),
    )  # fmt: skip
    assert code == 0, stdout
    records = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    assert sorted(r["controller"] for r in records) == ["orca", "orca", "straight_line", "straight_line"]
    table = (out / "table.md").read_text()
    assert TOY in table and " orca " in table


def test_a_plugin_around_the_mpc_keeps_its_warning_on_the_layout(capsys):
    """simulate leaves out the MPC's layout warnings for its own notes, which are for cmpc and dmpc: a
    plugin wrapping MPCController had the warning hidden and no note in its place."""
    wrapped = f"{TOYS}:WrappedMPC"
    argv = ["simulate", "--humans", "0", "--episodes", "2", "--no-progress", "--set", "env.time_limit=2"]
    code, _, err = run(capsys, "--plugin", wrapped, *argv, "--controller", wrapped)
    assert code == 0 and err.count("robots 0 and 1's goals lie 1.00 m apart, and the MPC keeps") == 1, err
    code, _, err = run(capsys, *argv, "--controller", "cmpc", "--set", "mpc.d_min=1.0")
    assert code == 0 and "goals lie" not in err and "note: the MPC's d_min 1 m is not well below" in err


def test_controllers_is_refused_outside_the_controllers_experiment(tmp_path, capsys):
    argv = ["sweep", "--experiment", "table2", "--controllers", "cmpc", "--dry-run", "--out", str(tmp_path)]
    code, _, err = run(capsys, *argv)
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "--controllers applies only to the experiments ['controllers'], not 'table2'" in err


def test_a_plugin_controller_runs_through_run_episode_like_a_shipped_one():
    register_controller_plugins([TOY])
    spec = ControllerSpec(TOY)
    assert spec.kind == registry.ControllerKind(uses_predictor=False, compiles=False)
    assert spec.predictor_name is None
    controller = make_controller(spec)
    result = run_episode(controller, seed=3, scenario="perpendicular", n_humans=4)
    assert result.controller == "straight_line" and result.metrics.success
    assert registry.controller_plugin(TOY).source == "plugin"


def test_a_net_plugin_is_still_a_model_kind():
    assert plugins.register_plugins([NET, TOY]) == ["model", "controller"]
    assert NET in model_names() and NET not in controller_names()
    assert os.environ[NETS_ENV] == NET and os.environ[registry.PLUGINS_ENV] == TOY


@pytest.mark.parametrize("register", [register_controller_plugins, plugins.register_plugins])
def test_one_plugin_given_alone_is_refused_naming_it(register):
    # a str is iterable: its letters were taken for plugins ("plugin 't' is not of the form module:Class")
    with pytest.raises(PipelineError, match=r"a list of 'module:Class' strings, got the str 'tests\.plugins"):
        register(TOY)


def test_a_new_process_sees_the_registered_controllers(tmp_path):
    register_controller_plugins([TOY])
    script = "from pipelines.loop.controllers import controller_names; print(controller_names())"
    done = subprocess.run(
        [sys.executable, "-c", script], cwd=REPO, env={**os.environ}, capture_output=True, text=True
    )
    assert done.returncode == 0 and done.stdout == f"{sorted([*SHIPPED, TOY])}\n"


def test_an_entry_point_names_a_controller(monkeypatch):
    entry = EntryPoint(name="straight_line", value=TOY, group=registry.ENTRY_POINT_GROUP)
    monkeypatch.setattr(registry.metadata, "entry_points", lambda group: [entry])
    assert controller_names() == sorted([*SHIPPED, "straight_line"])
    result = run_episode(
        make_controller(ControllerSpec("straight_line")), seed=0, scenario="circle", n_humans=2
    )
    assert result.metrics.success and registry.controller_plugin("straight_line").source == "entry point ?"
    assert make_controller(ControllerSpec("cmpc")).name == "cmpc"


def test_an_installed_entry_point_named_as_a_shipped_controller_is_refused(monkeypatch, tmp_path, capsys):
    """An installed package declaring ``cmpc = module:Class`` was ignored without a word (the shipped CMPC
    ran in its place): refused in one line naming the distribution and the entry point, wherever controllers
    are listed or built, and by simulate's --controller."""
    from tests.plugins import install_distribution

    group = registry.ENTRY_POINT_GROUP
    install_distribution(monkeypatch, tmp_path / "site", f"[{group}]\nstraight_line = {TOY}\ncmpc = {TOY}\n")
    message = (
        f"entry point 'cmpc' ({TOY}) of distribution 'shadow-pkg' would shadow a shipped controller; "
        f"rename it in shadow-pkg's '{group}' entry points or uninstall shadow-pkg"
    )
    for call in (
        controller_names,
        lambda: make_controller(ControllerSpec("cmpc")),
        lambda: make_controller(ControllerSpec("straight_line")),
    ):
        with pytest.raises(PipelineError) as refused:
            call()
        assert str(refused.value) == message
    line = parser_error(capsys, "simulate", "--controller", "cmpc")
    assert (
        line == f"crowdmpc simulate: error: argument --controller: {message}; see 'crowdmpc simulate --help'"
    )
    # a sweep refuses it before any worker (each episode failed with the traceback in errors.jsonl)
    out = tmp_path / "sweep"
    sweep = ["sweep", "--experiment", "baselines", "--humans", "3", "--episodes-per-cell", "1"]
    assert main([*sweep, "--backend", "inline", "--no-progress", "--out", str(out)]) == 2
    assert capsys.readouterr().err.strip() == f"crowdmpc sweep: error: {message}"
    assert not out.exists()


# ------------------------------------------------------------------------------------------ bad plugins
def test_an_unknown_controller_is_one_line_and_an_unregistered_plugin_is_never_imported(capsys):
    line = parser_error(capsys, "simulate", "--controller", "bogus")
    assert line == (
        "crowdmpc simulate: error: argument --controller: invalid choice: 'bogus' (choose from 'cmpc', "
        "'dmpc', 'orca', 'straight'); see 'crowdmpc simulate --help'"
    )
    line = parser_error(capsys, "simulate", "--controller", NEVER)
    assert line == (
        f"crowdmpc simulate: error: argument --controller: controller {NEVER!r} is a plugin that is not "
        f"registered; register it with `crowdmpc --plugin {NEVER} COMMAND ...` or "
        f"{registry.PLUGINS_ENV}={NEVER}; see 'crowdmpc simulate --help'"
    )
    assert "tests.plugins.never_imported" not in sys.modules
    with pytest.raises(UnknownController, match=r"unknown controller 'nope'; choose from \['cmpc', "):
        ControllerSpec("nope")
    register_controller_plugins([TOY])
    line = parser_error(capsys, "simulate", "--controller", "bogus")
    assert f"'straight', '{TOY}')" in line  # the registered plugins are choices too


@pytest.mark.parametrize(
    "plugin, message",
    [
        (
            f"{TOYS}:NoAct",
            f"model '{TOYS}:NoAct': <class '{TOYS}.NoAct'> is not a torch.nn.Module subclass (a predictor "
            "net), nor a controller class with reset, act, describe and close",
        ),
        (
            f"{TOYS}:BadFacts",
            f"controller '{TOYS}:BadFacts': BadFacts.uses_predictor must be a bool, got 'yes'",
        ),
        (
            "toy_controller.py",
            "plugin 'toy_controller.py' is not of the form module:NetClass or module:Controller",
        ),
        (f"{TOYS}:Nope", f"plugin '{TOYS}:Nope': module "),
    ],
)
def test_a_bad_plugin_is_a_one_line_parser_error(plugin, message, capsys):
    line = parser_error(capsys, "--plugin", plugin, "simulate", "--controller", "orca")
    assert line.startswith(f"crowdmpc: error: argument --plugin: {message}"), line
    assert registry.PLUGINS_ENV not in os.environ


def test_a_plugin_that_fails_to_build_is_one_line(capsys):
    broken = f"{TOYS}:Broken"
    code, stdout, err = run(capsys, "--plugin", broken, "simulate", "--controller", broken, "--no-progress")
    assert code == 2 and stdout == ""
    assert err == (
        f"crowdmpc simulate: error: controller {broken!r}: building it failed: ValueError: speed must be a "
        "positive number of m/s, got -1.0\n"
    )
    nameless = f"{TOYS}:Nameless"
    register_controller_plugins([nameless])
    with pytest.raises(PipelineError, match="needs a non-empty str name and a predictor"):
        make_controller(ControllerSpec(nameless))
    named = f"{TOYS}:NamedCmpc"
    register_controller_plugins([named])
    with pytest.raises(
        PipelineError, match=r"its name 'cmpc' is a shipped controller's, under which its rec"
    ):
        make_controller(ControllerSpec(named))


def test_a_plugin_whose_act_returns_no_control_output_is_one_line(capsys):
    bad = "tests.plugins.broken_controllers:ArrayAct"
    message = (
        "controller 'array_act' (ArrayAct): act() must return a crowdsim.control.ControlOutput, got "
        "numpy.ndarray"
    )
    argv = ["--plugin", bad, "simulate", "--controller", bad, "--humans", "2", "--episodes", "1"]
    code, stdout, err = run(capsys, *argv, "--no-progress")
    assert code == 1 and stdout == ""
    assert err == f"crowdmpc simulate: error: episode seed 0 (circle): {message}\n"
    with pytest.raises(PipelineError) as caught:
        run_episode(make_controller(ControllerSpec(bad)), seed=0, scenario="circle", n_humans=2)
    assert str(caught.value) == message


FAILING = "tests.plugins.failing_controllers"


@pytest.mark.parametrize(
    "name, problem",
    [
        ("AlwaysRaises", "reset() raised RuntimeError: broken build"),
        ("RaisesInAct", "act() raised RuntimeError: boom in act"),
        ("RaisesInDescribe", "describe() raised KeyError: 'version'"),
        ("RaisesInClose", "close() raised OSError: cannot release"),
    ],
)
def test_a_plugin_raising_in_a_method_is_one_line_naming_it_and_the_method(name, problem, capsys):
    """Each ended simulate with the plugin's traceback, taken for a bug in crowdmpc (a constructor raising was
    already one line)."""
    import gymnasium as gym

    import crowdsim
    from pipelines.loop.gym_loop import run_gym_episode
    from tests.plugins import failing_controllers

    plugin = f"{FAILING}:{name}"
    argv = ["--plugin", plugin, "simulate", "--controller", plugin, "--humans", "2", "--episodes", "1"]
    code, stdout, err = run(capsys, *argv, "--no-progress")
    controller = getattr(failing_controllers, name)(None, None)
    message = f"controller {controller.name!r} ({name}): {problem}"
    if name == "RaisesInClose":  # after the last episode: reported whole, no stop in its header
        after = " (after its one episode had finished)"
        assert (code, err) == (1, f"crowdmpc simulate: error: {message}{after}\n") and "success" in stdout
        assert "stopped by an error" not in stdout
    else:
        first = f"crowdmpc simulate: error: episode seed 0 (circle): {message}\n"
        assert (code, stdout, err) == (1, "", first)
    if name != "RaisesInClose":  # the loops never close the controller they are given
        with pytest.raises(PipelineError) as caught:
            run_gym_episode(controller, gym.make(crowdsim.ENV_ID, n_humans=2), seed=0)
        assert str(caught.value) == message


def test_a_shipped_controller_raising_or_ctrl_c_in_a_plugin_propagate_as_they_are(monkeypatch, capsys):
    """A shipped controller raising is a bug (its traceback); Ctrl-C in a plugin is the user's interrupt."""
    from pipelines.loop.baselines import BaselineController
    from tests.plugins.failing_controllers import InterruptedInAct

    with pytest.raises(KeyboardInterrupt):
        run_episode(InterruptedInAct(None, None), seed=0, scenario="circle", n_humans=2)
    plugin = f"{FAILING}:InterruptedInAct"
    argv = ["--plugin", plugin, "simulate", "--controller", plugin, "--humans", "2", "--episodes", "1"]
    assert run(capsys, *argv, "--no-progress")[0] == 130

    def broken(self, obs):
        raise RuntimeError("a bug")

    monkeypatch.setattr(BaselineController, "act", broken)
    with pytest.raises(RuntimeError, match="a bug"):
        run_episode(make_controller(ControllerSpec("orca")), seed=0, scenario="circle", n_humans=2)


BROKEN = "tests.plugins.broken_controllers"
BROKEN_CONTRACTS = [
    ("FlatPlan", "act() must return plan of shape (3, H, 2) or None, got shape (5,)"),
    ("PredictionOfRobots", "act() must return prediction of shape (H, 2, 2) or None, got shape (4, 3, 2)"),
    ("EmptyPlan", "act() must return plan of at least one step (H >= 1) or None, got shape (3, 0, 2)"),
    (
        "EmptyPrediction",
        "act() must return prediction of at least one step (H >= 1) or None, got shape (0, 2, 2)",
    ),
    ("IterationsNone", "act() must return iterations as an int, got None"),
    ("StatusNone", "act() must return status as a str, got None"),
    ("DescribeNone", "describe() must return a dict, got NoneType"),
    ("ConfigList", "describe()['config'] must be a dict, got list"),
    ("SeedInDescribe", "describe() must not set ['seed']: the episode sets them itself"),
    ("FallbackNumber", "act() must return fallback as a str or None, got 3"),
    ("SolveTimeNone", "act() must return solve_time_s as a number, got None"),
    ("PotentialText", "act() must return potential as a number or None, got 'x'"),
    (
        "BoolAccelerations",
        "act() must return accelerations of shape (3, 2), a row per robot, got bool values, not numbers",
    ),
    ("NaNAccelerations", "act() must return accelerations of finite numbers, got nan"),
    ("InfPlan", "act() must return plan of finite numbers, got inf"),
    (
        "NaNPrediction",
        "act() must return prediction of finite numbers (NaN only for every entry of a human not predicted), "
        "got nan",
    ),
    ("NegativeSolveTime", "act() must return solve_time_s as a finite number >= 0 (s), got -5.0"),
    ("NaNSolveTime", "act() must return solve_time_s as a finite number >= 0 (s), got nan"),
    ("NegativeIterations", "act() must return iterations as an int >= 0, got -1"),
    ("HugeIterations", f"act() must return iterations as an int >= 0, got {'1' + '0' * 39}"),
    ("BoolIterations", "act() must return iterations as an int, got True"),
    ("BoolSolveTime", "act() must return solve_time_s as a number, got False"),
    (
        "ObjectInConfig",
        "describe() must return JSON values (dicts, lists, strings, numbers, booleans, None), "
        "got Object of type object is not JSON serializable",
    ),
    ("NumberSha256", "describe()['predictor_sha256'] must be a str or None, got 123"),
    ("ExtraList", "act() must return extra as a dict, got list"),
    ("EnvInConfig", "describe()['config'] must not set 'env': the simulator's settings are recorded there"),
    (
        "IterationText",
        "act() must return iteration_predictions of (H, 2, 2) arrays, got shape () of <U1 values",
    ),
    ("IterationOfRobots", "act() must return iteration_predictions of (H, 2, 2) arrays, got shape (4, 3, 2)"),
    (
        "ObjectInExtra",
        "act() must return extra of JSON values (dicts, lists, strings, numbers, booleans, None), "
        "got Object of type object is not JSON serializable",
    ),
]


@pytest.mark.parametrize("name, problem", BROKEN_CONTRACTS)
def test_a_plugin_breaking_the_contract_is_one_line_naming_it_in_both_loops(name, problem):
    """Each was a traceback from the loop's bookkeeping (int(None), dict(None)) or, under --record, from the
    recorder drawing the plan; the loops now check what they take from a controller in one place."""
    import gymnasium as gym

    import crowdsim
    from pipelines.loop.gym_loop import run_gym_episode
    from tests.plugins import broken_controllers

    controller = getattr(broken_controllers, name)(None, None)
    message = f"controller {controller.name!r} ({name}): {problem}"
    with pytest.raises(PipelineError) as caught:
        run_episode(controller, seed=0, scenario="circle", n_humans=2)
    assert str(caught.value) == message
    with pytest.raises(PipelineError) as caught:
        run_gym_episode(controller, gym.make(crowdsim.ENV_ID, n_humans=2), seed=0)
    assert str(caught.value) == message


def test_the_callers_meta_takes_precedence_over_what_the_controller_describes():
    """run_episode's docstring: entries of ``meta`` are added last and take precedence over describe()'s."""
    from crowdsim.env_config import EnvConfig
    from pipelines.loop.contract import episode_meta

    episode = {"seed": 3, "scenario": "circle", "n_humans": 2, "n_robots": 3}
    described = {"note": "controller's", "kept": 1, "config": {"horizon": 8}}
    full = episode_meta(episode, EnvConfig(), "toy", None, described, {"note": "caller's"}, "test")
    assert (full["note"], full["kept"], full["seed"]) == ("caller's", 1, 3)
    assert full["config"]["horizon"] == 8 and full["config"]["env"]["dt"] == 0.4


def test_accelerations_as_a_list_of_rows_are_taken_and_recorded(tmp_path):
    """A list of rows is a valid (M, 2) array: the check passed it, and the recorder then called .tolist() on
    it; the loop hands every observer float arrays."""
    from pipelines.logs.reader import read_recording
    from pipelines.logs.recording import McapEpisodeRecorder
    from tests.plugins import broken_controllers

    recorder = McapEpisodeRecorder(tmp_path)
    result = run_episode(broken_controllers.RowsAsLists(None, None), seed=0, scenario="circle", n_humans=2,
                         observers=(recorder,))  # fmt: skip
    assert result.metrics is not None and read_recording(recorder.paths[0]).data("/robots")


def test_a_refused_describe_under_record_leaves_no_folder(tmp_path, capsys):
    """`simulate --record DIR` made DIR before a plugin's describe() was refused: an empty folder was left."""
    bad = f"{BROKEN}:DescribeNone"
    argv = ["--plugin", bad, "simulate", "--controller", bad, "--humans", "2", "--episodes", "1"]
    code, _, err = run(capsys, *argv, "--no-progress", "--record", str(tmp_path / "rec"))
    assert code == 1 and "describe() must return a dict" in err
    assert not (tmp_path / "rec").exists()


def test_a_wrong_plan_under_record_is_one_line(tmp_path, capsys):
    bad = f"{BROKEN}:FlatPlan"
    argv = ["--plugin", bad, "simulate", "--controller", bad, "--humans", "2", "--episodes", "1"]
    code, stdout, err = run(capsys, *argv, "--no-progress", "--record", str(tmp_path / "rec"))
    assert code == 1 and stdout == ""
    problem = f"controller 'flat_plan' (FlatPlan): {BROKEN_CONTRACTS[0][1]}"
    assert err == f"crowdmpc simulate: error: episode seed 0 (circle): {problem}\n"


def test_a_plugins_own_fallback_is_recorded_in_a_file_review_check_passes(tmp_path, capsys):
    """The guide lets act() say which fallback it used; the recording's schema knew only the MPCs' "shifted"
    and "brake", so simulate --record wrote files that review --check failed."""
    plugin = f"{BROKEN}:OwnFallback"
    argv = ["--plugin", plugin, "simulate", "--controller", plugin, "--humans", "2", "--episodes", "1"]
    code, _, err = run(capsys, *argv, "--no-progress", "--record", str(tmp_path / "rec"))
    assert code == 0, err
    code, out, err = run(capsys, "review", str(tmp_path / "rec"), "--check")
    assert code == 0 and "stop" not in err, out + err


@pytest.mark.parametrize(
    "name, predictor, message",
    [
        ("PredictingItsOwn", "constant_velocity",
         "a PredictingItsOwn has uses_predictor = True: its predictor must be spec.predictor "
         "'constant_velocity', got 'orca_oracle'"),
        ("PredictingNone", "orca_oracle",
         "a PredictingNone has uses_predictor = True: its predictor must be spec.predictor 'orca_oracle', "
         "got None"),
        ("HiddenPredictor", None,
         "a HiddenPredictor has uses_predictor = False: its predictor must be None, got 'constant_velocity' "
         "(uses_predictor = True plans with spec.predictor)"),
    ],
)  # fmt: skip
def test_a_plugin_naming_another_predictor_than_the_run_is_one_line(name, predictor, message, capsys):
    """The table and the cell keys named the spec's predictor while episodes.jsonl named the plugin's."""
    plugin = f"{TOYS}:{name}"
    argv = ["--plugin", plugin, "simulate", "--controller", plugin, "--humans", "2", "--episodes", "1"]
    if predictor is not None:
        argv += ["--predictor", predictor]
    code, stdout, err = run(capsys, *argv, "--no-progress")
    assert (code, stdout, err) == (2, "", f"crowdmpc simulate: error: controller {plugin!r}: {message}\n")


def test_a_plugin_planning_with_the_runs_predictor_runs_and_an_unknown_one_is_refused(tmp_path, capsys):
    """A plugin naming spec.predictor but never loading it ran with --predictor no_such_pred, rc 0, the header
    naming no_such_pred: an unknown predictor is refused before it is built, as cmpc refuses it."""
    plugin, out = f"{TOYS}:Predicting", tmp_path / "p.json"
    argv = ["--plugin", plugin, "simulate", "--controller", plugin, "--humans", "2", "--episodes", "1"]
    code, stdout, err = run(capsys, *argv, "--predictor", "orca_oracle", "--no-progress", "--json", str(out))
    assert code == 0 and stdout.startswith(f"controller {plugin} | predictor orca_oracle |"), err
    assert [e["predictor"] for e in json.loads(out.read_text())["episodes"]] == ["orca_oracle"]
    code, stdout, err = run(capsys, *argv, "--predictor", "no_such_pred", "--no-progress")
    assert (code, stdout) == (2, "")
    assert err.startswith("crowdmpc simulate: error: unknown predictor 'no_such_pred'; choose from [")
    assert err == run(capsys, *argv[2:4], "cmpc", *argv[5:], "--predictor", "no_such_pred")[2]


def test_the_guides_controller_runs_as_written(tmp_path, monkeypatch, capsys):
    """docs/extending.md's "Your own controller" example, saved as the user would, through simulate."""
    guide = (REPO / "docs" / "extending.md").read_text()
    section = guide.split("## 6. Your own controller", 1)[1]
    (tmp_path / "my_controller.py").write_text(section.split("```python\n", 1)[1].split("```", 1)[0])
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "my_controller", raising=False)
    plugin, out = "my_controller:GoStraight", tmp_path / "go.json"
    argv = ["--plugin", plugin, "simulate", "--controller", plugin, "--humans", "4", "--episodes", "2"]
    try:
        code, _, err = run(capsys, *argv, "--no-progress", "--json", str(out))
    finally:
        sys.modules.pop("my_controller", None)
    assert code == 0, err
    episodes = json.loads(out.read_text())["episodes"]
    assert [e["controller"] for e in episodes] == ["go_straight", "go_straight"]
    assert all(e["metrics"]["success"] and e["predictor"] is None for e in episodes)


def test_the_shipped_controllers_facts():
    """Which controllers name a predictor in their records and cell keys, and which --jit compiles: the MPCs
    both, ORCA and straight neither (a wrong fact silently drops --jit, or a predictor from a cell key)."""
    facts = {name: (k.uses_predictor, k.compiles) for name, k in registry.CONTROLLER_KINDS.items()}
    assert facts == {
        "straight": (False, False),
        "orca": (False, False),
        "cmpc": (True, True),
        "dmpc": (True, True),
    }


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"coupling": "joint"}, r"unknown coupling 'joint'; choose from \['ibr', 'nlp', 'none'\]"),
        ({"margins": "conformal"}, "margins must be a MarginSpec, got 'conformal'"),
        (
            {"mpc_overrides": (("human_margins", (0.1,)),)},
            "through ControllerSpec.margins, not mpc_overrides",
        ),
        # a truthy "no" would have left flocking on; 123 is no predictor's name
        ({"flocking": "no"}, "flocking must be True or False, got 'no'"),
        ({"record_iterations": "yes"}, "record_iterations must be True or False, got 'yes'"),
        ({"predictor": 123}, r"predictor must be a predictor's name \(a str\), got 123"),
        ({"predictor": None}, r"predictor must be a predictor's name \(a str\), got None"),
        ({"mpc_overrides": ("w_goal",)}, r"mpc_overrides must be a tuple of \(field, value\) pairs"),
    ],
    ids=[
        "coupling",
        "margins-text",
        "margins-override",
        "flocking",
        "record-iterations",
        "predictor-int",
        "predictor-none",
        "overrides-not-pairs",
    ],
)
def test_a_bad_controller_spec_is_refused(kwargs, message):
    with pytest.raises(PipelineError, match=message):
        ControllerSpec("cmpc", **kwargs)


def test_registering_a_plugin_keeps_those_listed_before(monkeypatch):
    """A second --plugin (or one registered after $CROWDMPC_CONTROLLERS named another) must not unlist the
    first from the worker processes, each listed once."""
    other = f"{TOYS}:Nameless"
    monkeypatch.setenv(registry.PLUGINS_ENV, other)
    register_controller_plugins([TOY, other])
    assert os.environ[registry.PLUGINS_ENV] == f"{other},{TOY}"


def test_a_plugin_spec_is_at_most_200_characters():
    name = "m" * 198 + ":C"  # 200 characters: MAX_PLUGIN_SPEC
    assert registry.is_plugin_spec(name) and not registry.is_plugin_spec("m" + name)


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        (f"{TOYS}:NoAct", r"NoAct has no act, describe, close \(the Controller protocol"),
        (f"{TOYS}:A_MAX", "is not a class"),
        ("not a plugin", "plugin 'not a plugin' is not of the form module:Class"),
    ],
    ids=["no-act", "not-a-class", "not-a-spec"],
)
def test_a_plugin_listed_in_the_environment_is_checked_like_one_given_to_plugin(spec, message):
    """$CROWDMPC_CONTROLLERS (set for worker processes, or by hand) skips the CLI's --plugin parsing: the
    registry itself must refuse what is no controller class, in one line."""
    with pytest.raises(PipelineError, match=message):
        registry.load_controller_plugin(spec)


_EDITED_CONTROLLER = """
class Mine:
    name = "mine_{version}"
    predictor = None
    def __init__(self, spec, env_config, *, jit=False): pass
    def reset(self, obs): pass
    def act(self, obs): raise NotImplementedError
    def describe(self): return {{}}
    def close(self): pass
"""
_EDITED_NET = """
from tests.plugins.toy_predictor import ToyNet
class Mine(ToyNet):
    version = {version}
"""


@pytest.mark.parametrize(("text", "lookup"), [(_EDITED_CONTROLLER, "controller"), (_EDITED_NET, "model")])
def test_registering_a_reloaded_plugin_again_takes_its_new_class(tmp_path, monkeypatch, text, lookup):
    """A notebook: register my_plugin:Mine, edit my_plugin.py, importlib.reload(my_plugin), register it again.
    The registry kept the class of the first registration, so the edited code never ran (nor any error
    said so); registering again now takes the module's class as it is, and one not reloaded stays as it
    was registered."""
    import importlib

    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "my_plugin", raising=False)
    source = tmp_path / "my_plugin.py"
    source.write_text(text.format(version=1))
    try:
        assert plugins.register("my_plugin:Mine") == lookup
        module = importlib.import_module("my_plugin")
        first = module.Mine
        assert plugins.register("my_plugin:Mine") == lookup  # the cell run again, nothing edited
        source.write_text(text.format(version=2))
        importlib.reload(module)
        assert module.Mine is not first
        plugins.register("my_plugin:Mine")
    finally:
        sys.modules.pop("my_plugin", None)
    if lookup == "controller":
        assert registry.controller_plugin("my_plugin:Mine").cls is module.Mine
    else:
        assert models.model_kind("my_plugin:Mine").net_class is module.Mine


def test_a_class_added_to_an_imported_module_is_told_to_reload_it(tmp_path, monkeypatch):
    """A notebook registers my_plugin:Mine before writing the class, then writes it and registers again:
    "module 'my_plugin' has no 'Mine'" both times, with nothing saying that Python keeps the module as it
    was first imported. The second refusal says to reload it; the first, from a fresh import, does not."""
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "my_plugin", raising=False)
    source = tmp_path / "my_plugin.py"
    source.write_text("")
    try:
        with pytest.raises(plugins.PluginError) as first:
            plugins.register("my_plugin:Mine")
        source.write_text(_EDITED_CONTROLLER.format(version=1))
        with pytest.raises(plugins.PluginError) as second:
            plugins.register("my_plugin:Mine")
    finally:
        sys.modules.pop("my_plugin", None)
    assert str(first.value) == "plugin 'my_plugin:Mine': module 'my_plugin' has no 'Mine'"
    assert str(second.value) == (
        "plugin 'my_plugin:Mine': module 'my_plugin' has no 'Mine'; if you added it since the module was "
        "imported, importlib.reload(my_plugin) first (Python keeps a module as it was first imported)"
    )


def test_a_plugin_changing_its_observation_in_place_changes_no_recording(tmp_path):
    """A controller that centres the scene on a robot in place (``obs.human_positions -= centre``) changed
    the observation the loop then handed the recorder: the MCAP's /robots and /humans (and review's plots)
    showed the moved positions while the metrics, from the simulator, were right. Each controller method
    gets a copy of its own, in both loops."""
    import gymnasium as gym

    import crowdsim
    from pipelines.logs.recording import McapEpisodeRecorder
    from pipelines.loop.gym_loop import run_gym_episode
    from tests.plugins import broken_controllers
    from tests.plugins.toy_controller import StraightLine

    def recorded(controller, folder, gym_loop):
        recorder = McapEpisodeRecorder(tmp_path / folder)
        if gym_loop:
            env = gym.make(crowdsim.ENV_ID, n_humans=2)
            run_gym_episode(controller, env, seed=0, observers=(recorder,))
        else:
            run_episode(controller, seed=0, scenario="circle", n_humans=2, observers=(recorder,))
        return _recorded_positions(recorder.paths[0])

    for gym_loop in (False, True):
        plain = recorded(StraightLine(None, None), f"plain{gym_loop}", gym_loop)
        centred = recorded(broken_controllers.CentresInPlace(None, None), f"centred{gym_loop}", gym_loop)
        assert centred == plain


def test_a_gym_policy_changing_info_observation_in_place_changes_no_recording(tmp_path):
    """``ObserveEpisodes`` recorded the observation it handed the policy in ``info``: a policy centring it in
    place moved the recorded positions of the step before."""
    import gymnasium as gym

    import crowdsim
    from pipelines.logs.recording import McapEpisodeRecorder
    from pipelines.loop.gym_loop import ObserveEpisodes
    from tests.plugins import broken_controllers
    from tests.plugins.toy_controller import StraightLine

    def recorded(folder, centre):
        policy = StraightLine(None, None)
        recorder = McapEpisodeRecorder(tmp_path / folder)
        env = ObserveEpisodes(gym.make(crowdsim.ENV_ID, n_humans=2), [recorder])
        _, info = env.reset(seed=0)
        done = False
        while not done:
            action = policy.act(info["observation"]).accelerations
            if centre:
                broken_controllers.centre_in_place(info["observation"])
            _, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
        return _recorded_positions(recorder.paths[0])

    assert recorded("centred", True) == recorded("plain", False)


def _recorded_positions(path: Path) -> list[tuple[int, list]]:
    """Each step's recorded robot and human positions of the MCAP file ``path``."""
    from pipelines.logs.reader import read_recording

    recording = read_recording(path)
    return [(m["step"], m["positions"]) for topic in ("/robots", "/humans") for m in recording.data(topic)]


def test_a_plugin_failing_in_a_later_episode_keeps_the_finished_ones_and_names_the_seed(tmp_path, capsys):
    """A plugin failing in episode 3 of 4 ended simulate with its one line, which named no episode, and
    without the summary or --json of the two episodes that had finished: a long run was lost, and its
    failure could not be rerun alone. It now reports those (as after Ctrl-C) and names the failing seed, and
    exits 1 as a sweep whose episodes raised does (it exited 2, a refused input's status, though two ran)."""
    from pipelines.errors import EPISODES_RAISED

    plugin = f"{FAILING}:NaNInThirdEpisode"
    report = tmp_path / "run.json"
    argv = ["--plugin", plugin, "simulate", "--controller", plugin, "--humans", "2", "--episodes", "4"]
    code, out, err = run(capsys, *argv, "--seed", "10", "--json", str(report), "--no-progress")
    problem = (
        "episode seed 12 (circle): controller 'nan_in_third_episode' (NaNInThirdEpisode): act() must return "
        "accelerations of finite numbers, got nan"
    )
    assert (code, err) == (EPISODES_RAISED, f"crowdmpc simulate: error: {problem}\n")
    assert "| stopped by an error: 2 episodes finished" in out
    payload = json.loads(report.read_text())
    assert payload["failed"] == {"seed": 12, "error": problem} and payload["episodes_finished"] == 2
    assert [e["seed"] for e in payload["episodes"]] == [10, 11] and payload["summary"]["episodes"] == 2


def test_a_plugin_nets_error_in_a_later_episode_keeps_the_finished_ones_and_names_the_seed(
    monkeypatch, capsys
):
    """A plugin net raising inside the MPC comes out of the episode as a PredictorError naming the predictor
    (LearnedPredictor), not a PipelineError: it is named by its episode and stops the run as one."""
    import pipelines.loop.episode as episode
    from predictors.errors import PredictorError

    original, calls = episode.run_episode, {"n": 0}

    def second_fails(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 2:
            raise PredictorError("predictor 'mine' (model 'my:Net'): encode raised ValueError: no")
        return original(*args, **kwargs)

    monkeypatch.setattr(episode, "run_episode", second_fails)
    argv = ["simulate", "--controller", "straight", "--humans", "2", "--episodes", "3", "--no-progress"]
    code, out, err = run(capsys, *argv)
    assert code == 1 and "| stopped by an error: 1 episodes finished" in out
    assert err == (
        "crowdmpc simulate: error: episode seed 1 (circle): predictor 'mine' (model 'my:Net'): encode raised "
        "ValueError: no\n"
    )


def test_plugins_registered_from_python_reach_the_sweeps_worker_processes(monkeypatch):
    """``load_controller_plugin`` and ``load_plugin`` register in this process and list nothing in the
    variables; a sweep's pool workers are spawned (on every OS), holding nothing this process imported: every
    episode of a script that registered that way was refused in the workers ("is a plugin that is not
    registered"), where the same sweep ran inline."""
    from pipelines.experiments.process_backend import ProcessBackend

    monkeypatch.delenv(NETS_ENV, raising=False)
    registry.load_controller_plugin(TOY)
    models.load_plugin(NET)
    backend = ProcessBackend(1, "none")
    try:
        in_worker = backend._pool.submit(registry.controller_kind, TOY).result(timeout=120)
        assert in_worker == registry.controller_kind(TOY)
        # the net's variable as well (its lookup, as the controller's above, would import torch: seconds)
        assert backend._pool.submit(os.getenv, NETS_ENV).result(timeout=120) == NET
    finally:
        backend.close()
    assert registry.PLUGINS_ENV not in os.environ and NETS_ENV not in os.environ  # the driver's unchanged


def test_a_worker_that_cannot_look_a_plugin_up_returns_the_episodes_error(monkeypatch):
    """A task's key names its controller's predictor, which for a plugin takes the plugin's class: a worker
    process where the plugin does not load (a class defined in a notebook, which a spawned worker cannot
    import) raised again computing the key for the error, so the exception left the worker and the sweep's
    driver ended in a traceback instead of errors.jsonl. The key the driver computed travels with the task."""
    import pickle

    from pipelines.experiments.tasks import Cell, EpisodeTask
    from pipelines.experiments.worker import EpisodeWorker

    registry.load_controller_plugin(TOY)
    task = EpisodeTask("mine", Cell("toy", ControllerSpec(TOY), 2), 0, "circle", 0)
    key = task.key  # the driver plans with it
    monkeypatch.setattr(registry, "_PLUGINS", {})  # a worker process: the plugin never loaded
    sent = pickle.loads(pickle.dumps(task))
    outcome = EpisodeWorker("none").run(sent)
    assert outcome.key == key and outcome.record is None
    assert "is a plugin that is not registered" in outcome.error.strip().splitlines()[-1]


def test_a_plugin_of_an_interactive_session_is_refused_before_workers_start(monkeypatch, tmp_path):
    """A notebook's class, registered as ``__main__:Class``, runs inline; a spawned worker's ``__main__`` is
    its own, so every episode of a pool's sweep failed, the shipped controllers' too, with "module
    '__main__' has no ...". A script's ``__main__`` the workers import again: that one is fine."""
    import types

    from pipelines.experiments.process_backend import ProcessBackend
    from tests.plugins.toy_controller import StraightLine

    session = types.ModuleType("__main__")  # a notebook's: no file, no module name
    session.StraightLine = StraightLine
    monkeypatch.setitem(sys.modules, "__main__", session)
    registry.load_controller_plugin("__main__:StraightLine")
    with pytest.raises(PipelineError, match=r"'__main__:StraightLine' is a class of this interactive"):
        ProcessBackend(1, "none")
    script = tmp_path / "run.py"
    script.write_text("")
    session.__file__ = str(script)  # a script's
    assert plugins.plugin_environment()[registry.PLUGINS_ENV] == "__main__:StraightLine"


def test_the_top_level_help_names_both_entry_point_groups_and_the_whole_protocol(capsys):
    """`crowdmpc --help` told plugin authors that installed packages declare entry points in the group
    "crowdmpc.predictors" only, so a controller package had no way to learn of "crowdmpc.controllers", and
    that a controller is a class with reset, act, describe and close, while one without `name` and
    `predictor` is refused (test_a_plugin_naming_another_predictor_than_the_run_is_one_line)."""
    with pytest.raises(SystemExit):
        main(["--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert f'"{models.ENTRY_POINT_GROUP}"' in text
    assert f'"{registry.ENTRY_POINT_GROUP}"' in text
    assert "name, predictor, reset, act, describe and close" in text


@pytest.mark.parametrize("backend", ["process", "inline"])
def test_a_sweep_closes_the_controllers_it_built(backend, tmp_path, monkeypatch, capsys):
    """Section 6 of docs/extending.md: ``close`` runs after the run (threads, solvers, a robot's hardware).
    A sweep closed none: each worker's cached controllers were dropped with the process."""
    log = tmp_path / "close.log"
    monkeypatch.setenv("CROWDMPC_TEST_CLOSE_LOG", str(log))
    logged = f"{TOYS}:Logged"
    code, stdout, _ = run(
        capsys, "--plugin", logged, "sweep", "--experiment", "controllers", "--controllers", logged,
        "--humans", "2,3", "--episodes-per-cell", "2", "--workers", "2", "--backend", backend,
        "--no-progress", "--out", str(tmp_path / "sweep"),
    )  # fmt: skip
    assert code == 0, stdout
    lines = log.read_text().split("\n")[:-1]
    built = sorted(line.split()[1] for line in lines if line.startswith("init"))
    closed = sorted(line.split()[1] for line in lines if line.startswith("close"))
    assert built and closed == built  # one close per controller built, in the process that built it


def test_a_controller_whose_close_raises_is_said_once_and_the_sweep_stands(tmp_path, capfd):
    raises = f"{TOYS}:CloseRaises"
    code = main(
        ["--plugin", raises, "sweep", "--experiment", "controllers", "--controllers", raises, "--humans", "2",
         "--episodes-per-cell", "2", "--backend", "inline", "--no-progress", "--out", str(tmp_path / "sw")]
    )  # fmt: skip
    assert code == 0
    err = capfd.readouterr().err
    line = "note: controller 'straight_line''s close() raised OSError: the serial port is gone"
    assert err.count(line) == 1


def test_a_plugin_of_the_working_folder_reaches_workers_that_move_to_their_scratch(tmp_path):
    """With jit a sweep's workers move to their scratch folders before they import the plugins: once the
    plugin's folder was searched by a finder of the driver's (not on sys.path, which spawned workers copy),
    every episode raised "No module named 'mine_q'"; it imports a module of its folder too. Run as a user
    runs it, the `crowdmpc` script in the plugin's folder (pytest's own sys.path hid it)."""
    (tmp_path / "helper_q.py").write_text("SPEED = 0.7\n", encoding="utf-8")
    source = (REPO / "tests" / "plugins" / "toy_controller.py").read_text(encoding="utf-8")
    extra = "\nfrom helper_q import SPEED  # noqa: E402\n"
    extra += "\n\nclass Compiling(StraightLine):\n    compiles = True\n"
    (tmp_path / "mine_q.py").write_text(source + extra, encoding="utf-8")
    mine = "mine_q:Compiling"  # its kind compiles: --jit on moves the workers to their scratch folders
    argv = ["--plugin", mine, "sweep", "--experiment", "controllers", "--controllers", f"orca,{mine}"]
    argv += ["--humans", "2", "--episodes-per-cell", "1", "--workers", "2", "--jit", "on", "--no-progress"]
    done = subprocess.run(
        [str(Path(sys.executable).with_name("crowdmpc")), *argv, "--out", str(tmp_path / "sweep")],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert len((tmp_path / "sweep" / "episodes.jsonl").read_text().splitlines()) == 2
