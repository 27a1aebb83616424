"""A sweep's [env] and [env.orca] values (``World.env_settings``): every cell simulated with them over its
profile's, its key naming them, its episodes simulate's with the same settings; [world] stays refused."""

import json

import pytest

from pipelines.cli import main
from pipelines.errors import PipelineError
from pipelines.experiments.tasks import ENV_SETTINGS, World


def test_settings_reach_the_simulator_and_the_key_and_none_keep_the_old_key():
    world = World(profile="v1").with_env({"time_limit": 50.0, "orca.time_horizon": 2.0})
    assert world.env_settings == (("orca.time_horizon", 2.0), ("time_limit", 50.0))  # sorted: one key
    assert world.label == "v1-visible-orca.time_horizon=2.0-time_limit=50.0"
    env = world.env_config()
    assert (env.time_limit, env.orca.time_horizon, env.orca.neighbor_dist, env.profile) == (
        50.0,
        2.0,
        10.0,
        "v1",
    )
    assert env.success_rule == "first_reach"  # the rest stays v1's
    assert World().label == "paper-visible" and World().env_config() == World().with_env({}).env_config()
    sensed = World(crowd="eth_test").sensing(3.0).with_env({"formation": "wedge"})
    assert sensed.label == "paper-visible-sensed3m-eth_test-formation=wedge"
    assert set(ENV_SETTINGS) >= {"crossing", "formation", "orca.max_neighbors", "time_limit"}


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        ({"dt": 0.2}, r"unknown simulator settings \['dt'\]; a sweep sets \["),
        ({"orca.time_horizon": 0.0}, "OrcaParams.time_horizon must be a number of at least"),
        ({"crossing": "diagonal"}, "EnvConfig.crossing must be one of"),
    ],
)
def test_a_setting_the_simulator_refuses_is_refused_in_one_line(settings, message):
    with pytest.raises(PipelineError, match=message):
        World().with_env(settings)
    with pytest.raises(PipelineError, match="each key once, sorted"):
        World(env_settings=(("time_limit", 50.0), ("crossing", "v1")))


def test_a_sweep_runs_its_env_settings_as_simulate_does_and_says_so(tmp_path):
    sets = ["--set", "env.orca.time_horizon=2", "--set", "env.time_limit=50"]
    out = tmp_path / "sw"
    sweep = ["sweep", "--experiment", "table2", "--humans", "5", "--episodes-per-cell", "1", "--backend"]
    assert main([*sets, *sweep, "inline", "--no-progress", "--out", str(out)]) == 0
    records = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    cmpc = next(r for r in records if r["controller"] == "cmpc")
    assert cmpc["cell"].endswith("-paper-visible-orca.time_horizon=2.0-time_limit=50.0-h5-r3")
    assert (
        cmpc["config"]["env"]["orca"]["time_horizon"] == 2.0 and cmpc["config"]["env"]["time_limit"] == 50.0
    )
    table = (out / "table.md").read_text()
    assert "; simulator orca.time_horizon = 2.0, time_limit = 50.0" in table.splitlines()[0]
    assert "Simulator settings over the profile's: orca.time_horizon=2.0, time_limit=50.0." in table
    simulate = ["simulate", "--controller", "cmpc", "--predictor", "social_lstm_eth", "--humans", "5"]
    simulate += ["--scenario", "circle", "--seed", "0", "--no-progress"]
    for settings, equal in ((sets, True), ([], False)):
        path = tmp_path / f"sim{len(settings)}.json"
        assert main([*settings, *simulate, "--json", str(path)]) == 0
        (episode,) = json.loads(path.read_text())["episodes"]
        assert (episode["metrics"] == cmpc["metrics"]) is equal  # the settings act: without them, other


def _keys(capsys) -> dict[str, str]:
    """A dry run's cell key by column label."""
    lines = [line for line in capsys.readouterr().out.splitlines() if " humans " in line]
    return {line.split(" humans ")[0].rsplit(maxsplit=1)[0].strip(): line.split()[-1] for line in lines}


def test_vary_a_simulator_setting_gives_every_method_a_column_per_value(tmp_path, capsys):
    """The profile's own value (ORCA's 5 s) is the cell without --vary; ORCA and the straight line vary too
    (the humans are everyone's)."""
    sweep = ["sweep", "--humans", "7", "--dry-run", "--out", str(tmp_path / "sw"), "--experiment"]
    assert main([*sweep, "table2", "--vary", "env.orca.time_horizon=2,5"]) == 0
    plain = "social_lstm_eth-F-ibr-m=none-paper-visible"
    assert _keys(capsys) == {
        "CMPC orca.time_horizon=2.0": f"cmpc-{plain}-orca.time_horizon=2.0-h7-r3",
        "CMPC orca.time_horizon=5.0": f"cmpc-{plain}-h7-r3",
        "DMPC orca.time_horizon=2.0": f"dmpc-{plain}-orca.time_horizon=2.0-h7-r3",
        "DMPC orca.time_horizon=5.0": f"dmpc-{plain}-h7-r3",
    }
    grid = ["--vary", "env.time_limit=30,60", "--vary", "mpc.d_min=0.8,0.9"]
    assert main([*sweep, "baselines", "--vary", "env.time_limit=30,60"]) == 0
    assert sorted(_keys(capsys)) == [
        "ORCA time_limit=30.0",
        "ORCA time_limit=60.0",
        "straight time_limit=30.0",
        "straight time_limit=60.0",
    ]
    assert main([*sweep, "table2", *grid]) == 0
    keys = _keys(capsys)
    assert len(keys) == 8 and keys["CMPC d_min=0.9 time_limit=60.0"].endswith(
        "d_min=0.9-m=none-paper-visible-time_limit=60.0-h7-r3"
    )


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (
            ["--set", "env.orca.time_horizon=2", "--vary", "env.orca.time_horizon=2,5"],
            "--vary and --set env.orca.time_horizon both set env.orca.time_horizon: give its values once",
        ),
        (["--vary", "env.profile=paper,v1"], "only an [mpc] setting (mpc.KEY=V1,V2,...), the margins"),
        (
            ["--vary", "env.orca.time_horizon=2,0"],
            "--vary value 0 must be a number of at least 1e-06 s, got 0.0",
        ),
        (["--vary", "env.crossing=paper,diagonal"], "--vary value diagonal must be one of"),
    ],
)
def test_a_simulator_variation_that_cannot_run_is_refused_in_one_line(options, message, tmp_path, capsys):
    argv = ["sweep", "--experiment", "table2", "--dry-run", "--out", str(tmp_path / "sw"), *options]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


def test_vary_the_sensor_range_gives_every_method_a_column_per_range(tmp_path, capsys):
    """Each column the cell `--sensor-range R` makes; the sensing experiment, which compares ranges itself,
    and a run that sets one range refuse it."""
    sweep = ["sweep", "--humans", "7", "--dry-run", "--out", str(tmp_path / "sw"), "--experiment"]
    assert main([*sweep, "table2", "--vary", "simulate.sensor_range=2,3"]) == 0
    plain = "social_lstm_eth-F-ibr-m=none-paper-visible"
    assert _keys(capsys) == {
        "CMPC sensor_range=2.0": f"cmpc-{plain}-sensed2m-h7-r3",
        "CMPC sensor_range=3.0": f"cmpc-{plain}-sensed3m-h7-r3",
        "DMPC sensor_range=2.0": f"dmpc-{plain}-sensed2m-h7-r3",
        "DMPC sensor_range=3.0": f"dmpc-{plain}-sensed3m-h7-r3",
    }
    assert main([*sweep, "table2", "--sensor-range", "3"]) == 0
    assert set(_keys(capsys).values()) == {f"cmpc-{plain}-sensed3m-h7-r3", f"dmpc-{plain}-sensed3m-h7-r3"}
    for options, message in (
        (["sensing", "--vary", "simulate.sensor_range=2,3"], "experiment 'sensing' compares sensor ranges"),
        (
            ["table2", "--sensor-range", "3", "--vary", "simulate.sensor_range=2,3"],
            "both set simulate.sensor",
        ),
        (["table2", "--vary", "simulate.sensor_range=2,0"], "must be a finite number of metres > 0, got 0.0"),
    ):
        assert main([*sweep, *options]) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1


def test_table_notes_name_only_the_simulator_settings_every_column_shares():
    """`--vary env.time_limit=3,40`: the notes said "Simulator settings over the profile's: time_limit=3.0"
    of the whole table (40 is the profile's own, a column without settings); each column's label says it."""
    from pipelines.commands.sweep_plan import configured_experiment
    from pipelines.config import load
    from pipelines.experiments.safety_report import world_note

    def note(*sets: str) -> str:
        experiment = configured_experiment(load(sets=["sweep.experiment=baselines", *sets]))
        return world_note(list(experiment.cells((3,))))[0]

    assert "Simulator settings" not in note('sweep.vary="env.time_limit=3,40"')
    shared = note('sweep.vary="env.orca.time_horizon=2,5"', "env.time_limit=50")
    assert shared.endswith("Simulator settings over the profile's: time_limit=50.0.")


def test_success_is_paired_only_with_a_column_of_the_same_placement():
    """The spawn separation places other humans from a seed (seed 1, 7 humans, circle), so `--vary
    env.spawn_separation=0.1,1` gives each value its own reference, and DMPC is paired with CMPC of its value;
    the humans' ORCA horizon (the same people, who then move otherwise) keeps one reference. Hand-made
    outcomes, 4 crowds each: CMPC at 0.1 succeeds on all, the others fail crowds 0 and 1. Paired with CMPC
    at 0.1, CMPC at 1 read "+0 / −2 (p = 0.5)", losses on crowds it never faced."""
    import numpy as np

    from crowdsim.scenarios import make_layout
    from pipelines.commands.sweep_plan import configured_experiment
    from pipelines.config import load
    from pipelines.experiments.summary import summarize
    from pipelines.experiments.tables import markdown_table
    from tests.pipelines.test_small_fixes import _records

    near, far = (
        make_layout("circle", 7, 3, np.random.default_rng(1), spawn_separation=s).human_starts
        for s in (0.1, 1)
    )
    assert not np.allclose(near, far)
    won, lost = (True, False, False, False), (False, False, False, False)

    def paired(vary: str) -> list[str]:
        sets = ["sweep.experiment=table2", "sweep.humans=[7]", f'sweep.vary="{vary}"']
        experiment = configured_experiment(load(sets=sets))
        outcomes = {(label, 7): [lost, lost, won, won] for label in experiment.method_labels}
        outcomes[experiment.method_labels[0], 7] = [won] * 4
        table = markdown_table(
            experiment, summarize(experiment, experiment.cells(), _records(experiment, outcomes))
        )
        line = next(line for line in table.splitlines() if line.startswith("| Success, paired"))
        return line.removesuffix(" |").split(" | ")[1:]

    assert paired("env.spawn_separation=0.1,1") == [
        "reference",
        "reference",
        "+0 / −2 (p = 0.5)",
        "+0 / −0 (p = 1)",
    ]
    assert (
        paired("env.orca.time_horizon=2,5") == ["reference", "+0 / −2 (p = 0.5)"] + ["+0 / −2 (p = 0.5)"] * 2
    )
