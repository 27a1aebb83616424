"""A user's predictor through the command line: ``crowdmpc --plugin module:NetClass`` for train, zoo,
evaluate, simulate and ``sweep --experiment predictors --predictors a,b,c`` (whose workers load the plugin
too), and every way to get it wrong as one line, exit 2."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from pipelines.cli import main
from pipelines.experiments.methods import SWAP_PREDICTORS, swap_predictors
from predictors import models
from predictors.data.prepare import prepare_ewap
from predictors.models import PLUGINS_ENV
from predictors.registry import load_predictor
from predictors.zoo import user_zoo_dir, zoo_names
from tests.cli_calls import one_line, parser_error
from tests.cli_calls import run_cli as run
from tests.predictors.samples import write_tiny_ewap, write_walk_file

REPO = Path(__file__).resolve().parents[2]
TOY = "tests.plugins.toy_predictor:ToyNet"
NEVER = "tests.plugins.never_imported:Net"  # importing that module raises


@pytest.fixture(autouse=True)
def _private_dirs(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path_factory.mktemp("cache")))


# ---------------------------------------------------------------------------------------------- the flow
def test_a_plugin_from_training_to_the_swap_table(tmp_path, capsys):
    data = write_walk_file(tmp_path / "walk.ndjson")
    out = tmp_path / "run"
    code, stdout, _ = run(
        capsys, "--plugin", TOY, "train", "--model", TOY, "--net-config", '{"hidden_dim": 4}',
        "--train", str(data), "--val", str(data), "--epochs", "1", "--batch-size", "2", "--out", str(out),
        "--no-progress",
    )  # fmt: skip
    assert code == 0
    weights = out / "toy_net_custom.pt"
    assert f"`crowdmpc --plugin {TOY} zoo add {weights}`" in stdout
    config = json.loads(weights.with_suffix(".json").read_text())
    assert config["model"] == TOY and config["net"] == {"hidden_dim": 4, "radius": 2.0}
    assert os.environ[PLUGINS_ENV] == TOY  # for the processes the commands start

    code, stdout, _ = run(capsys, "--plugin", TOY, "zoo", "add", str(weights), "--name", "toy_walk")
    assert code == 0 and (user_zoo_dir() / "toy_walk.pt").is_file()
    assert load_predictor("toy_walk").kind == TOY

    raw = write_tiny_ewap(tmp_path / "data")
    prepared = tmp_path / "prepared"
    prepare_ewap(raw, prepared, categorize_scenes=False, log=lambda msg: None)
    code, stdout, _ = run(
        capsys, "--plugin", TOY, "evaluate", "--predictor", "toy_walk", "--data-dir", str(prepared),
        "--no-progress",
    )  # fmt: skip
    assert code == 0 and "ADE [m]" in stdout

    result = tmp_path / "sim.json"
    code, _, _ = run(
        capsys, "--plugin", TOY, "simulate", "--controller", "cmpc", "--predictor", "toy_walk",
        "--humans", "2", "--robots", "1", "--episodes", "1", "--json", str(result), "--no-progress",
    )  # fmt: skip
    assert code == 0 and json.loads(result.read_text())["run"]["predictor"] == "toy_walk"

    sweep = tmp_path / "sweep"
    code, stdout, _ = run(
        capsys, "--plugin", TOY, "sweep", "--experiment", "predictors",
        "--predictors", "constant_velocity,toy_walk", "--humans", "2", "--robots", "1",
        "--episodes-per-cell", "1", "--backend", "process", "--workers", "1", "--jit", "off",
        "--no-progress", "--out", str(sweep),
    )  # fmt: skip
    assert code == 0  # the worker process loaded the plugin (CROWDMPC_PLUGINS) and the user zoo's model
    records = [json.loads(line) for line in (sweep / "episodes.jsonl").read_text().splitlines()]
    assert sorted(r["key"].split("-")[1] for r in records) == ["constant_velocity", "toy_walk"]
    assert "toy_walk" in stdout


def test_a_new_process_loads_a_plugin_model_only_with_the_plugin_registered(tmp_path):
    weights = _toy_checkpoint(tmp_path)
    assert main(["--plugin", TOY, "zoo", "add", str(weights), "--name", "toy_walk"]) == 0
    script = "from predictors.registry import load_predictor; print(load_predictor('toy_walk').kind)"
    env = {**os.environ}
    done = subprocess.run([sys.executable, "-c", script], cwd=REPO, env=env, capture_output=True, text=True)
    assert done.returncode == 0 and done.stdout == f"{TOY}\n"  # CROWDMPC_PLUGINS, set by --plugin
    env.pop(PLUGINS_ENV)
    export = [sys.executable, "-m", "pipelines.cli", "export", "toy_walk", "--out", str(tmp_path / "x")]
    done = subprocess.run(export, cwd=REPO, env=env, capture_output=True, text=True)
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr == _no_plugin_line("export") + "\n"


def _toy_checkpoint(tmp_path: Path, name: str = "toy", metrics: str = "{}") -> Path:
    """The toy plugin's net saved as ``name`` in tmp_path/run, with ``metrics`` as its metrics file."""
    from predictors.checkpoint import save_checkpoint
    from predictors.models import load_plugin

    kind = load_plugin(TOY)
    (tmp_path / "run").mkdir()
    weights, _ = save_checkpoint(
        kind.build_net(kind.config({"hidden_dim": 4})),
        model=TOY,
        name=name,
        out_dir=tmp_path / "run",
        obs_len=9,
    )
    (tmp_path / "run" / f"{name}.metrics.json").write_text(metrics)
    return weights


def _no_plugin_line(command: str) -> str:
    """The one line ``command`` refuses the user zoo's toy_walk with, its plugin not registered."""
    manifest = user_zoo_dir() / "manifest.json"
    return (
        f"crowdmpc {command}: error: predictor 'toy_walk' of the user zoo ({manifest}): model {TOY!r} is a "
        f"plugin that is not registered; register it with `crowdmpc --plugin {TOY} COMMAND ...` or "
        f"{PLUGINS_ENV}={TOY}"
    )


# ------------------------------------------------------------------------------------------- bad plugins
@pytest.mark.parametrize(
    "spec, message",
    [
        ("../x", "plugin '../x' is not of the form module:NetClass"),
        ("my_predictor.py", "plugin 'my_predictor.py' is not of the form module:NetClass"),
        ("os:system", "model 'os:system': <built-in function system> is not a torch.nn.Module subclass"),
        (
            "no_such_module_q:Net",
            "plugin 'no_such_module_q:Net': importing 'no_such_module_q' failed: ModuleNotFoundError: "
            "No module named 'no_such_module_q'",
        ),
        ("tests.plugins.toy_predictor:Nope", "plugin 'tests.plugins.toy_predictor:Nope': module "),
    ],
)
def test_a_bad_plugin_is_a_one_line_error(spec, message, capsys):
    line = parser_error(capsys, "--plugin", spec, "zoo", "list")
    assert line.startswith(f"crowdmpc: error: argument --plugin: {message}"), line
    assert line.endswith("; see 'crowdmpc --help'"), line
    assert PLUGINS_ENV not in os.environ


def test_a_plugin_named_by_its_file_or_run_from_another_folder_says_what_to_write(
    tmp_path, monkeypatch, capsys
):
    """A newcomer's three slips with docs/extending.md's ``--plugin window_mlp:WindowMLP``: running from
    another folder than the file's ("No module named 'mine_q'", nothing said of where crowdmpc looked),
    naming the file for the module, and giving its path. A module the plugin imports that is missing keeps
    its own message, which names it."""
    monkeypatch.chdir(tmp_path)
    here = Path.cwd()  # as the command sees it (tmp_path may be reached through a link)
    (tmp_path / "needs_q_dep.py").write_text("import no_such_dep_q\n")
    said = {
        spec: parser_error(capsys, "--plugin", spec, "zoo", "list")
        for spec in ("mine_q:Net", "mine_q.py:Net", "./sub/mine_q.py:Net", "needs_q_dep:Net")
    }
    assert said["mine_q:Net"] == (
        "crowdmpc: error: argument --plugin: plugin 'mine_q:Net': importing 'mine_q' failed: "
        "ModuleNotFoundError: No module named 'mine_q' (not installed, and no mine_q.py nor mine_q/ in the "
        f"folder crowdmpc runs in, {here}: run it from the folder that holds mine_q.py, or put that "
        "folder on PYTHONPATH); see 'crowdmpc --help'"
    )
    assert said["mine_q.py:Net"].endswith(
        "No module named 'mine_q' (name the module, not its file: mine_q:Net); see 'crowdmpc --help'"
    )
    assert said["./sub/mine_q.py:Net"] == (
        "crowdmpc: error: argument --plugin: plugin './sub/mine_q.py:Net' is not of the form "
        "module:NetClass or module:Controller (a module's name as Python imports it, not a file: run "
        "crowdmpc from the folder that holds mine_q.py and write mine_q:Net); see 'crowdmpc --help'"
    )
    assert said["needs_q_dep:Net"].endswith(
        "importing 'needs_q_dep' failed: ModuleNotFoundError: No module named 'no_such_dep_q'; see "
        "'crowdmpc --help'"
    )


def test_a_plugin_file_named_as_crowdmpcs_own_package_is_told_to_be_renamed(tmp_path, monkeypatch, capsys):
    """It said "module 'mpc' has no 'MyNet'; ... importlib.reload(mpc) first", of crowdmpc's mpc package."""
    import mpc

    (tmp_path / "mpc.py").write_text("class MyNet:\n    pass\n", encoding="utf-8")
    monkeypatch.chdir(tmp_path)
    line = parser_error(capsys, "--plugin", "mpc:MyNet", "zoo", "list")
    assert line == (
        f"crowdmpc: error: argument --plugin: plugin 'mpc:MyNet': module 'mpc' is {mpc.__file__}, not your "
        f"{tmp_path / 'mpc.py'}: an installed module (or crowdmpc's own) of that name comes first; rename "
        "your file; see 'crowdmpc --help'"
    )


def test_a_plugin_file_linked_from_elsewhere_is_the_users_own(tmp_path, monkeypatch, capsys):
    """A link in the working folder to one's own file elsewhere was taken for another module of that name."""
    (tmp_path / "shared").mkdir()
    (tmp_path / "shared" / "linked_nets_q.py").write_text("class Other:\n    pass\n", encoding="utf-8")
    (tmp_path / "work").mkdir()
    (tmp_path / "work" / "linked_nets_q.py").symlink_to(tmp_path / "shared" / "linked_nets_q.py")
    monkeypatch.chdir(tmp_path / "work")
    monkeypatch.syspath_prepend(str(tmp_path / "work"))
    line = parser_error(capsys, "--plugin", "linked_nets_q:MyNet", "zoo", "list")
    assert line.startswith(
        "crowdmpc: error: argument --plugin: plugin 'linked_nets_q:MyNet': module 'linked_nets_q' has no "
        "'MyNet'"
    ), line


def test_an_unregistered_plugin_kind_is_refused_by_train_and_never_imported(capsys):
    line = parser_error(capsys, "train", "--model", NEVER)
    assert line == (
        f"crowdmpc train: error: argument --model: model {NEVER!r} is a plugin that is not registered; "
        f"register it with `crowdmpc --plugin {NEVER} COMMAND ...` or {PLUGINS_ENV}={NEVER}; "
        "see 'crowdmpc train --help'"
    )
    assert "tests.plugins.never_imported" not in sys.modules
    line = parser_error(capsys, "train", "--model", "gpt")
    assert line.startswith("crowdmpc train: error: argument --model: unknown model 'gpt'; choose from [")


def test_a_plugin_of_one_kind_named_where_the_other_is_wanted_is_told_its_kind(monkeypatch, capsys):
    """Each said "is a plugin that is not registered; register it with --plugin ...", the plugin the user had
    just registered."""
    from pipelines.loop import spec
    from pipelines.loop.spec import PLUGINS_ENV as CONTROLLERS_ENV

    monkeypatch.setattr(models, "_PLUGINS", {})
    monkeypatch.setattr(spec, "_PLUGINS", {})
    for variable in (PLUGINS_ENV, CONTROLLERS_ENV):
        monkeypatch.setenv(variable, "")
    net, controller = TOY, "tests.plugins.toy_controller:StraightLine"
    line = parser_error(capsys, "--plugin", net, "simulate", "--controller", net)
    assert line == (
        f"crowdmpc simulate: error: argument --controller: controller {net!r} is registered as a predictor "
        "net (an nn.Module), not a controller (a class with reset, act, describe and close, "
        "docs/extending.md); a net drives cmpc or dmpc: --controller cmpc --predictor NAME, once trained and "
        "in the zoo; see 'crowdmpc simulate --help'"
    )
    line = parser_error(capsys, "--plugin", controller, "train", "--model", controller)
    assert line == (
        f"crowdmpc train: error: argument --model: model {controller!r} is registered as a controller (a "
        "class with reset and act), not a predictor net (an nn.Module with encode and decode_step, "
        "docs/extending.md): train takes a net; see 'crowdmpc train --help'"
    )


def test_the_sweep_refuses_a_plugin_model_whose_plugin_is_not_registered(tmp_path, monkeypatch, capsys):
    weights = _toy_checkpoint(tmp_path)
    assert main(["--plugin", TOY, "zoo", "add", str(weights), "--name", "toy_walk"]) == 0
    monkeypatch.setattr(models, "_PLUGINS", {})  # a new process, without --plugin
    monkeypatch.delenv(PLUGINS_ENV)
    code, _, err = run(
        capsys, "sweep", "--experiment", "predictors", "--predictors", "constant_velocity,toy_walk",
        "--backend", "inline", "--out", str(tmp_path / "sweep"),
    )  # fmt: skip
    assert code == 2 and one_line(err) == _no_plugin_line("sweep")
    assert not (tmp_path / "sweep" / "episodes.jsonl").exists()


@pytest.mark.parametrize(
    "argv",
    [
        ("simulate", "--controller", "cmpc", "--predictor", "toy_walk", "--humans", "2", "--robots", "1",
         "--no-progress"),
        ("sweep", "--experiment", "predictors", "--predictors", "constant_velocity,toy_walk", "--backend",
         "inline", "--dry-run"),
        ("evaluate", "--predictor", "toy_walk", "--no-progress"),
        ("export", "toy_walk"),
        ("calibrate", "--predictor", "toy_walk", "--source", "real", "--dry-run", "--no-progress"),
    ],
    ids=lambda argv: argv[0],
)  # fmt: skip
def test_every_command_refuses_a_plugin_model_without_its_plugin_in_one_line(
    argv, tmp_path, monkeypatch, capsys
):
    """Each loaded the entry and named its config file alone (".../toy_walk.json: "model": ..."), where the
    sweep named the entry and its zoo: one check now, naming the entry, its manifest, the kind and how to
    register it."""
    weights = _toy_checkpoint(tmp_path)
    assert main(["--plugin", TOY, "zoo", "add", str(weights), "--name", "toy_walk"]) == 0
    monkeypatch.setattr(models, "_PLUGINS", {})  # a new process, without --plugin
    monkeypatch.delenv(PLUGINS_ENV)
    out = ["--out", str(tmp_path / ("x.casadi" if argv[0] == "export" else "sweep"))]
    code, _, err = run(capsys, *argv, *(out if argv[0] in ("export", "sweep") else ()))
    assert code == 2 and one_line(err) == _no_plugin_line(argv[0])


# ------------------------------------------------------------------------------------------- --predictors
def test_a_calibrate_command_offered_for_a_plugin_model_registers_its_plugin(tmp_path, capsys):
    """The note's command, run as printed, failed with "a plugin that is not registered"."""
    from predictors.calibration_store import recalibrate_command

    weights = _toy_checkpoint(tmp_path)
    assert main(["--plugin", TOY, "zoo", "add", str(weights), "--name", "toy_walk"]) == 0
    assert recalibrate_command("toy_walk", "closed-loop", 0.1) == (
        f"crowdmpc --plugin {TOY} calibrate --predictor toy_walk --source closed-loop --alpha 0.1"
    )
    # the model kind a command located already, as its notes hand it over
    assert recalibrate_command("toy_walk", "closed-loop", 0.1, kind=TOY) == recalibrate_command(
        "toy_walk", "closed-loop", 0.1
    )
    assert recalibrate_command("toy_walk", "closed-loop", 0.1, kind=None).startswith("crowdmpc calibrate ")
    assert recalibrate_command("social_lstm_eth", "real", 0.05, 3.0, False) == (
        "crowdmpc calibrate --predictor social_lstm_eth --source real --alpha 0.05 --sensor-range 3 "
        "--no-sensor-tracks"
    )


def test_the_default_swap_table_takes_the_later_models_once_a_zoo_has_them():
    assert "social_gru_eth" in SWAP_PREDICTORS
    assert swap_predictors(()) == (
        "constant_velocity", "vanilla_lstm_eth", "social_lstm_eth", "social_lstm_soft_eth", "social_gan_eth",
        "social_lstm_synth", "orca_oracle",
    )  # fmt: skip
    assert swap_predictors({"social_gru_eth"})[5:7] == ("social_gru_eth", "social_lstm_synth")


def test_predictors_lists_the_swap_table(tmp_path, capsys):
    code, stdout, _ = run(
        capsys, "sweep", "--experiment", "predictors", "--predictors", "constant_velocity, orca_oracle",
        "--dry-run", "--out", str(tmp_path),
    )  # fmt: skip
    assert code == 0
    assert [line.split()[0] for line in stdout.splitlines()[1:]] == ["constant_velocity", "orca_oracle"]
    code, stdout, _ = run(capsys, "sweep", "--experiment", "predictors", "--dry-run", "--out", str(tmp_path))
    shipped = swap_predictors(set(zoo_names()))  # the shipped zoo's GRU and attention models included
    assert "social_gru_eth" in shipped and "social_attention_eth" in shipped
    assert code == 0 and stdout.startswith("Predictor swap") and len(stdout.splitlines()) == 1 + len(shipped)


@pytest.mark.parametrize(
    "options, message",
    [
        (
            ["--experiment", "table2", "--predictors", "constant_velocity"],
            "--predictors applies only to the experiments ['predictors'], not 'table2' (use --predictor to "
            "replace every method's predictor)",
        ),
        (
            ["--experiment", "baselines", "--predictors", "constant_velocity"],
            "--predictors applies only to the experiments ['predictors'], not 'baselines'",
        ),
        (
            ["--experiment", "predictors", "--predictors", "constant_velocity,constant_velocity"],
            "--predictors must name each predictor once, got 'constant_velocity' more than once",
        ),
        (
            ["--experiment", "predictors", "--predictors", "constant_velocity,nope"],
            "experiment 'predictors' needs predictors ['nope'] that are not available",
        ),
    ],
)
def test_bad_predictor_lists_are_one_line(tmp_path, capsys, options, message):
    code, _, err = run(capsys, "sweep", *options, "--backend", "inline", "--out", str(tmp_path / "s"))
    line = one_line(err)
    assert code == 2 and line.startswith(f"crowdmpc sweep: error: {message}"), line
    assert not (tmp_path / "s" / "episodes.jsonl").exists()


@pytest.mark.parametrize(
    "options, message",
    [
        (
            ["--experiment", "table2", "--set", 'sweep.predictors=["constant_velocity"]'],
            "--set sweep.predictors: [sweep] predictors applies only to the experiments ['predictors'], not "
            "'table2' (use [controller] predictor to replace",
        ),
        (
            ["--experiment", "conventions", "--set", "env.profile=v1"],
            "--set env.profile: experiment 'conventions' fixes each method's profile and visibility; [env] "
            "profile and robots_visible do not apply",
        ),
        (
            ["--experiment", "baselines", "--set", "controller.margins=fixed:0.1"],
            "--set controller.margins: experiment 'baselines' fixes each method's margins; [controller] "
            "margins does not apply",
        ),
    ],
)
def test_a_refused_config_value_is_not_called_an_option(tmp_path, capsys, options, message):
    """The experiment's refusal named the option (--predictors, --profile and --visibility, --margins) of a
    value set by --set or a config file, none of which was given."""
    code, _, err = run(capsys, "sweep", *options, "--backend", "inline", "--out", str(tmp_path / "s"))
    line = one_line(err)
    assert code == 2 and line.startswith(f"crowdmpc sweep: error: {message}"), line


@pytest.mark.parametrize("value", ["../x,a", ",", "a/b", "x" * 65])
def test_predictor_names_are_checked_by_the_parser(tmp_path, capsys, value):
    line = parser_error(
        capsys, "sweep", "--experiment", "predictors", "--predictors", value, "--out", str(tmp_path)
    )
    assert line.startswith("crowdmpc sweep: error: argument --predictors: ")
    assert line.endswith(
        (
            "is not a predictor name; see 'crowdmpc sweep --help'",
            "an empty item in ','; separate the values by single commas; see 'crowdmpc sweep --help'",
        )
    )


# -------------------------------------------------------------------------------------- train's options
@pytest.mark.parametrize(
    "options, message",
    [
        (
            ["--model", "social_attention", "--pooling", "soft"],
            "--pooling does not apply to social_attention",
        ),
        (
            ["--model", "vanilla_lstm", "--pooling", "soft"],
            "--pooling does not apply to vanilla_lstm (it has no social pooling)",
        ),
        (
            ["--model", "vanilla_lstm", "--net-config", '{"pooling": "grid"}'],
            "--net-config: vanilla_lstm: pooling 'grid' is not a vanilla_lstm: the kind is defined by "
            "pooling 'none' (it has no social pooling)",
        ),
        (
            ["--model", "social_lstm", "--pooling", "max"],
            "--pooling: social_lstm: pooling 'max' is not one of",
        ),
        (["--model", "social_lstm", "--net-config", "[1]"], "--net-config must be a JSON object"),
        (["--model", "social_lstm", "--net-config", "{"], "--net-config: not valid JSON"),
        (  # json kept the last of a key typed twice: a 64-unit net trained without a word
            ["--model", "social_lstm", "--net-config", '{"hidden_dim": 32, "hidden_dim": 64}'],
            "--net-config: the key 'hidden_dim' appears twice in one object; give each key once",
        ),
        (["--model", "social_lstm", "--net-config", "[" * 100_000], "--net-config: 100000 characters"),
        (
            ["--model", "social_gru", "--net-config", '{"bogus": 1}'],
            "--net-config: social_gru: unknown social_gru config keys ['bogus']",
        ),
        (
            ["--model", "social_lstm", "--net-config", '{"hidden_dim": 10000000}'],
            "--net-config: social_lstm: hidden_dim must be in 1..4096",
        ),
        (
            ["--model", "social_lstm", "--pooling", "grid", "--net-config", '{"pooling": "soft"}'],
            "--pooling and --net-config both set pooling",
        ),
        (
            ["--model", TOY, "--net-config", '{"radius": -1}'],
            f"--net-config: {TOY} config: ValueError",
        ),
        (  # a config class with a field of no default: the values come from --net-config
            ["--model", "tests.plugins.broken_nets:NoDefaults"],
            "tests.plugins.broken_nets:NoDefaults config: TypeError: NoDefaultsConfig.__init__() missing 1 "
            "required positional argument: 'width'; give the values its config has no default for with "
            "--net-config '{\"key\": ...}'",
        ),
        (["--model", "social_lstm", "--name", "../x"], "--name '../x' is not allowed"),
    ],
)
def test_train_options_are_checked_in_one_line(tmp_path, capsys, options, message):
    data = write_walk_file(tmp_path / "walk.ndjson")
    plugins = ["--plugin", TOY, "--plugin", "tests.plugins.broken_nets:NoDefaults"]
    argv = [*plugins, "train", *options, "--train", str(data), "--val", str(data)]
    code, _, err = run(capsys, *argv, "--out", str(tmp_path / "run"), "--no-progress")
    line = one_line(err)
    assert code == 2 and line.startswith(f"crowdmpc train: error: {message}"), line
    assert not (tmp_path / "run").exists()


def test_a_stray_file_named_as_crowdmpcs_own_package_beside_a_plugin_shadows_nothing(tmp_path):
    """In a fresh interpreter (a sweep's worker), importing a plugin from the working folder put that folder
    on sys.path before crowdmpc's packages had been imported, and an editable install is found after every
    sys.path entry: a notes file mpc.py beside the plugin became crowdmpc's ``mpc`` ("No module named
    'mpc.cmpc'; 'mpc' is not a package"), and every episode of the sweep raised."""
    (tmp_path / "mpc.py").write_text("# notes\n", encoding="utf-8")
    (tmp_path / "pipelines.py").write_text("# notes\n", encoding="utf-8")
    (tmp_path / "my_plugin_q.py").write_text("class Thing:\n    pass\n", encoding="utf-8")
    code = (
        "from predictors.plugin_import import import_class\n"
        "print(import_class('my_plugin_q:Thing').__module__)\n"
        "import mpc.cmpc, pipelines.cli\n"
        "print(mpc.__file__ != 'mpc.py' and mpc.__path__ is not None, pipelines.cli.__name__)\n"
    )
    # -P: the working folder is not put first on sys.path, as for the `crowdmpc` script and its workers.
    # PYTHONPATH as this process has it, but absolute: a relative one (PYTHONPATH=. in the checkout) would
    # name tmp_path in the child, the user's own choice of putting the stray files first, not crowdmpc's.
    env = dict(os.environ)
    if env.get("PYTHONPATH"):
        env["PYTHONPATH"] = os.pathsep.join(
            os.path.abspath(p) for p in env["PYTHONPATH"].split(os.pathsep) if p
        )
    done = subprocess.run(
        [sys.executable, "-P", "-c", code],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["my_plugin_q", "True", "pipelines.cli"]


def test_a_manifest_entry_naming_a_kind_no_plugin_registers_runs_as_its_config_says(
    tmp_path, monkeypatch, capsys
):
    """The config, whose sha256 the entry holds, builds the model (`zoo verify` names an entry that says
    otherwise): simulate ran a user entry whose manifest "model" was edited to a kind nothing registers,
    while the sweep refused it, "predictor 'mine' of the user zoo: unknown model 'no_such_kind'"."""
    import hashlib
    import shutil

    from predictors import zoo

    src = tmp_path / "src"
    src.mkdir()
    for suffix in (".pt", ".json"):
        shutil.copyfile(zoo.shipped_checkpoints_dir() / f"social_lstm_eth{suffix}", src / f"mine{suffix}")
    sha = {
        suffix: hashlib.sha256((src / f"mine{suffix}").read_bytes()).hexdigest()
        for suffix in (".pt", ".json")
    }
    recorded = {"weights_sha256": sha[".pt"], "config_sha256": sha[".json"], "model": "social_lstm"}
    (src / "mine.metrics.json").write_text(json.dumps({**recorded, "metrics": {}}))
    monkeypatch.setenv(zoo.ZOO_ENV, str(tmp_path / "zoo"))
    monkeypatch.chdir(tmp_path)
    assert main(["zoo", "add", str(src / "mine.pt")]) == 0
    manifest = tmp_path / "zoo" / zoo.MANIFEST_NAME
    document = json.loads(manifest.read_text())
    document["models"][0]["model"] = "no_such_kind"
    manifest.write_text(json.dumps(document))
    small = ["--predictor", "mine", "--humans", "2", "--robots", "1", "--episodes", "1"]
    code, _, err = run(
        capsys, "simulate", "--controller", "cmpc", *small, "--no-progress", "--set", "env.time_limit=2"
    )
    assert code == 0, err
    code, _, err = run(
        capsys, "sweep", "--experiment", "table2", *small, "--dry-run", "--out", str(tmp_path / "s")
    )
    assert code == 0, err
    [problem] = [problem for located, problem in zoo.verify_entries() if located.entry.name == "mine"]
    assert (
        problem is not None
        and "entry 'mine' says model 'no_such_kind', its config mine.json 'social_lstm'" in problem
    )
