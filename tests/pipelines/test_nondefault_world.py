"""`crowdmpc simulate` with [world] values other than the paper's: what it prints follows them."""

import json

import pytest

from pipelines.cli import main


@pytest.mark.parametrize(("radius", "label"), [(0.3, "contact (<0.6 m)"), (0.45, "contact (<0.9 m)")])
def test_the_printed_contact_threshold_is_the_runs_sum_of_radii(tmp_path, capsys, radius, label):
    """Contact is a centre distance below the sum of the radii, 2 x [world] radius (crowdsim.metrics). With
    radius 0.45 the table read "contact (<0.6 m) 100 %" over episodes whose closest approach was 0.62 to
    0.83 m, under "collision (<0.8 m) 75 %": a contact that is no collision."""
    out = tmp_path / "run.json"
    argv = ["simulate", "--controller", "straight", "--humans", "5", "--episodes", "4", "--no-progress"]
    assert main([*argv, "--set", f"world.radius={radius}", "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert label in printed
    episodes = [e["metrics"] for e in json.loads(out.read_text())["episodes"]]
    assert all(e["contact"] == (e["min_distance"] < 2 * radius) for e in episodes)
    if radius != 0.3:  # some episode whose contact only the run's threshold explains
        assert any(e["contact"] and e["min_distance"] >= 0.6 for e in episodes)


@pytest.mark.parametrize("margins", ["conformal", "conformal-motion", "conformal-shortfall"])
def test_calibrated_margins_are_refused_at_another_tau(margins):
    """Every calibration measures errors k steps of 0.4 s ahead (TrajNet++'s 2.5 Hz, or `crowdmpc calibrate`'s
    default world). The ORCA oracle, the one predictor that plans at another tau, planned at tau = 0.25 s
    with its closed-loop margins [0, 2.8e-6, 0.0065, 0.0267] m: the errors 0.4 to 1.6 s ahead applied 0.25 to
    1 s ahead. Fixed margins, given per step, stay allowed."""
    from crowdsim.env_config import EnvConfig
    from pipelines.errors import PipelineError
    from pipelines.loop.controllers import ControllerSpec, make_controller
    from pipelines.loop.margins import parse_margins

    spec = ControllerSpec("cmpc", "orca_oracle", margins=parse_margins(margins))
    with pytest.raises(
        PipelineError, match=r"per step of 0.4 s but the simulator's tau is 0.25 s \(\[world\] dt\)"
    ):
        make_controller(spec, EnvConfig(dt=0.25))
    fixed = ControllerSpec("cmpc", "orca_oracle", margins=parse_margins("fixed:0,0,0.01,0.03"))
    assert make_controller(fixed, EnvConfig(dt=0.25)).cfg.human_margins == (0.0, 0.0, 0.01, 0.03)


@pytest.mark.parametrize("predictor", ["constant_velocity", "social_lstm_eth"])
def test_a_predictor_at_another_tau_is_refused_naming_it_and_the_key(capsys, predictor):
    """The refusal said "the predictors are sampled every 0.4 s, the simulator's tau is 0.2 s": neither which
    predictor nor which setting, nor what would run."""
    argv = ["simulate", "--controller", "cmpc", "--predictor", predictor, "--set", "world.dt=0.2"]
    assert main([*argv, "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert f"the predictor {predictor} reads positions sampled every 0.4 s" in err[0]
    assert (
        "the simulator's tau is 0.2 s ([world] dt): set --set world.dt=0.4, or plan with orca_oracle"
        in err[0]
    )


def test_steps_the_wall_time_budget_cut_short_are_printed(tmp_path, capsys):
    """mpc.time_limit_s (1 s) is far above a step's time at Table I's horizon, not at every horizon:
    Social-GAN at horizon 20 had 14 of 39 steps stop their IBR loop at it and 5 solves run past it, which the
    JSON's statuses held but the printed table did not (it showed "fallback steps 5 of 39" only). A budget no
    step can meet stands in for that here; a run within it prints no such row."""
    out = tmp_path / "run.json"
    argv = ["simulate", "--controller", "cmpc", "--humans", "2", "--no-progress", "--set", "env.time_limit=4"]
    assert main([*argv, "--set", "mpc.time_limit_s=1e-6", "--json", str(out)]) == 0
    summary = json.loads(out.read_text())["summary"]
    steps, longest = summary["control_steps"], summary["solve_time_max_ms"] / 1e3
    expected = (
        f"wall-time budget         {steps} of {steps} steps reached mpc.time_limit_s = 1e-06 s, the longest "
        f"step {longest:.3g} s; a step whose solve reached it brakes (a Fatrop solve only once it has run to "
        "its end): their plans"
    )
    assert expected in capsys.readouterr().out  # the step's length said: the budget did not bound it
    assert main(argv) == 0
    assert "wall-time budget" not in capsys.readouterr().out


@pytest.mark.parametrize(
    ("settings", "d_min", "contact"),
    [(["mpc.d_min=0.5"], "0.5", "0.6"), (["world.radius=0.45"], "0.8", "0.9")],
    ids=["d_min-below", "radius-above"],
)
def test_an_mpc_whose_d_min_is_below_the_contact_distance_is_refused(capsys, settings, d_min, contact):
    """Eqs. 11 and 12 keep d_min between centres; below the sum of the radii that distance is a contact, which
    the MPC then accepts in its plans: `--set mpc.d_min=0.5` ran (9 humans, seeds 0-5: within 0.8 m of a human
    in 6 of 6 episodes, in contact in 1), and so did `--set world.radius=0.45` under Table I's 0.8 m."""
    argv = ["simulate", "--controller", "cmpc", "--humans", "3", "--no-progress"]
    for item in settings:
        argv += ["--set", item]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    contact_line = f"the MPC's d_min {d_min} m is below the contact distance 2 x [world] radius = {contact} m"
    assert contact_line in err[0]
    assert f"set [mpc] d_min >= {contact}" in err[0]


def test_d_min_at_the_contact_distance_and_baselines_with_any_radius_still_run(capsys):
    """The refusal is the MPC's: d_min equal to 2 x radius plans no contact, and straight and ORCA robots
    plan with no d_min."""
    argv = ["simulate", "--humans", "3", "--no-progress"]
    assert main([*argv, "--controller", "cmpc", "--set", "mpc.d_min=0.6"]) == 0
    assert main([*argv, "--controller", "orca", "--set", "world.radius=0.45"]) == 0


def test_make_controller_refuses_an_mpc_whose_d_min_is_below_the_contact_distance():
    from crowdsim.env_config import EnvConfig
    from pipelines.errors import PipelineError
    from pipelines.loop.controllers import ControllerSpec, make_controller

    spec = ControllerSpec("dmpc", "constant_velocity", mpc_overrides=(("d_min", 1.0),))
    with pytest.raises(PipelineError, match=r"d_min 1 m is below the contact distance .* = 1.1 m"):
        make_controller(spec, EnvConfig(radius=0.55))


@pytest.mark.parametrize(
    ("radius", "d_min", "advice"),
    [
        ("1e-6", "1e-7", ""),  # at the least radius
        ("2e-6", "1e-7", ""),  # above it, but d_min needs a radius of 5e-08 m, below the least
        ("0.3", "1e-9", ""),
        ("2e-6", "2e-6", ", or a smaller [world] radius"),  # the least radius, 1e-06 m, would do
        ("0.3", "0.5", ", or a smaller [world] radius"),
    ],
)
def test_the_refusal_offers_a_smaller_radius_only_where_one_is_allowed(capsys, radius, d_min, advice):
    """At [world] radius 1e-06 m, crowdsim.world's least, `--set mpc.d_min=1e-7` was told "or a smaller
    [world] radius", which is refused; so was it above the least where the radius d_min needs (d_min / 2)
    is below it (`--set world.radius=2e-6 --set mpc.d_min=1e-7`: 5e-08 m "must be at least 1e-06 m")."""
    argv = ["simulate", "--controller", "cmpc", "--humans", "1", "--robots", "1", "--no-progress"]
    assert main([*argv, "--set", f"world.radius={radius}", "--set", f"mpc.d_min={d_min}"]) == 2
    contact = f"{2 * float(radius):g}"
    assert capsys.readouterr().err.strip() == (
        f"crowdmpc simulate: error: --set mpc.d_min: the MPC's d_min {float(d_min):g} m is below the contact "
        f"distance 2 x [world] radius = {contact} m: its plans would touch humans and teammates (Eqs. 11 "
        f"and 12 keep d_min between centres); set [mpc] d_min >= {contact} (--set mpc.d_min={contact})"
        f"{advice}"
    )


def test_config_show_says_what_d_min_must_be_and_what_the_collision_rate_counts(capsys):
    """A study that changes [mpc] d_min or [world] radius reads the bound CMPC and DMPC enforce, and that the
    collision rate stays Table I's 0.8 m, from the annotated defaults."""
    assert main(["config", "show"]) == 0
    line = next(row for row in capsys.readouterr().out.splitlines() if row.startswith("d_min = "))
    assert "at least 2 x [world] radius" in line and "the collision rate counts 0.8 m" in line


def test_a_config_file_run_from_python_is_the_simulate_run(tmp_path):
    """README, "Your own study": pipelines.config.load, the spec built from it and run_episodes give the
    episodes `crowdmpc --config FILE simulate` gives, metric for metric (a non-default world and MPC)."""
    from pipelines.config import load
    from pipelines.loop.controllers import ControllerSpec
    from pipelines.loop.episode import run_episodes
    from pipelines.loop.margins import parse_margins

    config = tmp_path / "run.toml"
    config.write_text("[world]\nradius = 0.35\n[scenario]\nhumans = 4\n[mpc]\nd_min = 0.9\n")
    cfg = load(str(config), ["scenario.robots=2"])
    spec = ControllerSpec(
        "dmpc",
        "constant_velocity",
        mpc_overrides=cfg.mpc_overrides(),
        margins=parse_margins(cfg.controller.margins or "none"),
    )
    results = run_episodes(
        spec,
        episodes=2,
        seed=0,
        scenario=cfg.scenario.name,
        n_humans=cfg.scenario.humans,
        n_robots=cfg.scenario.robots,
        env_config=cfg.env,
        progress=False,
    )
    out = tmp_path / "run.json"
    argv = ["--config", str(config), "--set", "scenario.robots=2", "simulate", "--controller", "dmpc"]
    assert main([*argv, "--episodes", "2", "--no-progress", "--json", str(out)]) == 0
    recorded = [e["metrics"] for e in json.loads(out.read_text())["episodes"]]
    assert [r.record().metrics.as_dict() for r in results] == recorded


def test_a_controller_built_for_another_world_is_refused_by_the_loops():
    """make_controller(spec) builds for the default world; run in a simulator of v_max 0.5 m/s and radius
    0.45 m it ran silently, its MPC planning at 1 m/s (the simulator clipping every plan) and keeping Table
    I's d_min inside the contact distance: only another tau was refused (at reset). The loops know both
    worlds; an environment of the same world but other settings (a time limit) still runs."""
    import gymnasium as gym

    import crowdsim
    from crowdsim.env_config import EnvConfig
    from pipelines.errors import PipelineError
    from pipelines.loop.controllers import ControllerSpec, make_controller
    from pipelines.loop.episode import run_episode
    from pipelines.loop.gym_loop import run_gym_episode

    other = EnvConfig(v_max=0.5, radius=0.45)
    message = r"built for another world \(radius 0.3 m there, 0.45 here; v_max 1 m/s there, 0.5 here\)"
    for name in ("cmpc", "orca"):
        controller = make_controller(ControllerSpec(name, "constant_velocity"))
        with pytest.raises(PipelineError, match="run_episode: .*" + message):
            run_episode(controller, seed=0, scenario="circle", n_humans=2, env_config=other)
        with pytest.raises(PipelineError, match="run_gym_episode: .*" + message):
            run_gym_episode(controller, gym.make(crowdsim.ENV_ID, n_humans=2, config=other), seed=0)
    controller = make_controller(ControllerSpec("straight"))
    longer = EnvConfig(time_limit=60.0)
    assert run_episode(controller, seed=0, scenario="circle", n_humans=2, env_config=longer).metrics.success


def test_a_controller_moving_by_orca_built_for_other_orca_settings_is_refused_by_the_loops():
    """The ORCA oracle predicts the humans by the simulator it was built for (whether they see the robots,
    their ORCA parameters), the ORCA baseline drives its robots by its ORCA parameters: built by
    make_controller(spec) for the default simulator and run among humans blind to the robots, the oracle
    predicted them dodging (0.12 m off one step ahead, where it is exact), silently. An MPC predicting with a
    model reads none of them and still runs."""
    import dataclasses

    import gymnasium as gym

    import crowdsim
    from crowdsim.env_config import EnvConfig
    from pipelines.errors import PipelineError
    from pipelines.loop.controllers import ControllerSpec, make_controller
    from pipelines.loop.episode import run_episode
    from pipelines.loop.gym_loop import run_gym_episode
    from predictors.oracle import ORACLE_PREDICTOR

    blind = EnvConfig(robots_visible=False)
    oracle = make_controller(ControllerSpec("cmpc", ORACLE_PREDICTOR))
    message = (
        r"moves by the ORCA settings of the simulator it was built for \(robots_visible True there, False"
    )
    with pytest.raises(PipelineError, match="run_episode: the controller 'cmpc' " + message):
        run_episode(oracle, seed=0, scenario="circle", n_humans=2, env_config=blind)
    with pytest.raises(PipelineError, match="run_gym_episode: .*" + message):
        run_gym_episode(oracle, gym.make(crowdsim.ENV_ID, n_humans=2, config=blind), seed=0)
    tighter = EnvConfig(orca=dataclasses.replace(EnvConfig().orca, time_horizon=2.0))
    with pytest.raises(PipelineError, match=r"run_episode: the controller 'orca' .*\(orca OrcaParams\("):
        run_episode(
            make_controller(ControllerSpec("orca")), seed=0, scenario="circle", n_humans=2, env_config=tighter
        )
    for name in ("cmpc", "orca"):  # built for it: runs
        built = make_controller(ControllerSpec(name, ORACLE_PREDICTOR), blind)
        assert run_episode(built, seed=0, scenario="circle", n_humans=2, env_config=blind).metrics.n_steps
    model = make_controller(ControllerSpec("cmpc", "constant_velocity"))
    assert run_episode(model, seed=0, scenario="circle", n_humans=2, env_config=blind).metrics.n_steps
