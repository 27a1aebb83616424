"""CMPC/DMPC as closed-loop controllers, driven through crowdsim's CrowdEnv."""

import dataclasses
import re

import numpy as np
import pytest

from crowdsim.env import CrowdEnv
from mpc.dynamics import braking
from mpc.errors import MPCConfigError
from pipelines.errors import ActBeforeResetWarning, PipelineError
from pipelines.loop.controllers import ControllerSpec, make_controller
from pipelines.loop.episode import run_episode
from pipelines.loop.mpc import MPCController
from pipelines.loop.mpc_setup import check_history, mpc_config, predictor_history


class Collect:
    def __init__(self):
        self.outputs = []

    def on_reset(self, obs, meta):
        pass

    def on_step(self, obs, out, next_obs):
        self.outputs.append(out)

    def on_end(self, result):
        pass


def first_step(spec, n_humans=3, seed=0):
    env = CrowdEnv()
    obs = env.reset(seed, "circle", n_humans)
    controller = make_controller(spec)
    controller.reset(obs)
    return obs, controller.act(obs)


@pytest.mark.parametrize("name", ["cmpc", "dmpc"])
def test_control_output_fields(name):
    obs, out = first_step(ControllerSpec(name))
    h = 4
    assert out.accelerations.shape == (3, 2) and np.all(np.abs(out.accelerations) <= 2.0 + 1e-9)
    assert out.plan.shape == (3, h, 2) and out.prediction.shape == (h, 3, 2)
    assert out.status == "ok" and out.fallback is None and out.iterations >= 1
    assert out.solve_time_s > 0 and np.isfinite(out.potential)
    assert out.iteration_predictions == ()
    assert {"solves", "solver_iterations", "converged"} <= set(out.extra)
    # Constant velocity: every human keeps its current velocity (zero at the start).
    np.testing.assert_allclose(out.prediction, np.broadcast_to(obs.human_positions, (h, 3, 2)))


def test_record_iterations_keeps_every_iterations_prediction():
    _, out = first_step(ControllerSpec("cmpc", record_iterations=True))
    assert len(out.iteration_predictions) == out.iterations == 2


def test_spec_options_reach_the_config():
    controller = MPCController(
        ControllerSpec("cmpc", flocking=False, mpc_overrides=(("horizon", 5), ("j_max", 3))),
        distributed=False,
    )
    assert controller.cfg.w_floc == 0.0 and controller.cfg.horizon == 5 and controller.cfg.j_max == 3
    with pytest.raises(MPCConfigError, match="horizn"):
        MPCController(ControllerSpec("cmpc", mpc_overrides=(("horizn", 5),)), distributed=False)
    with pytest.raises(MPCConfigError, match="horizon"):
        MPCController(ControllerSpec("cmpc", mpc_overrides=(("horizon", 0),)), distributed=False)


@pytest.mark.parametrize("name", ["cmpc", "dmpc"])
@pytest.mark.parametrize(
    "override, message",
    [
        (("rho", 2000.0), r"^rho must be at most 1000 s\^2, got 2000.0$"),
        (("delta", 1e-300), r"^delta must be at least 1e-40, got 1e-300$"),
    ],
)
def test_an_mpc_its_nlp_cannot_solve_is_refused_before_any_solve(name, override, message):
    """MPCConfig holds a value beyond the NLP's bounds (a config a sweep folder recorded reads back): the
    controller builds its NLP as it resets, which refuses it, and so does a step without a reset."""
    obs = CrowdEnv().reset(0, "circle", 2)
    controller = MPCController(ControllerSpec(name, mpc_overrides=(override,)), distributed=name == "dmpc")
    with pytest.raises(MPCConfigError, match=message):
        controller.reset(obs)
    with pytest.raises(MPCConfigError, match=message), pytest.warns(ActBeforeResetWarning):
        MPCController(ControllerSpec(name, mpc_overrides=(override,)), distributed=name == "dmpc").act(obs)


def test_jit_compiles_the_ibr_nlps_only():
    assert mpc_config(ControllerSpec("cmpc"), jit=True).jit
    assert not mpc_config(ControllerSpec("cmpc"), jit=False).jit
    # the coupled NLP's graph holds the network: compiling it took minutes (mpc_config's docstring)
    assert not mpc_config(ControllerSpec("cmpc", "social_lstm_soft_eth", coupling="nlp"), jit=True).jit


def test_the_coupled_nlp_is_not_compiled_when_the_mpc_overrides_ask_either(monkeypatch):
    """``[mpc] jit = true`` (mpc_overrides) compiles the IBR NLPs; for the coupled NLP it is set off, so that
    one config file serves both couplings. Checked where the solvers are built, without running gcc."""
    import mpc.solvers

    compiled = ControllerSpec("cmpc", mpc_overrides=(("jit", True),))
    assert mpc_config(compiled).jit
    coupled = dataclasses.replace(compiled, coupling="nlp")
    assert not mpc_config(coupled).jit and not mpc_config(coupled, jit=True).jit
    builds, build = [], mpc.solvers.build_nlpsol

    def spy(name, plugin, nlp, options, jit):
        builds.append((plugin, jit))
        return build(name, plugin, nlp, options, False)  # never gcc, even when asked

    monkeypatch.setattr(mpc.solvers, "build_nlpsol", spy)
    MPCController(coupled, distributed=False).reset(CrowdEnv().reset(0, "circle", 3))
    assert builds and not any(jit for _, jit in builds)


def test_coupled_nlp_is_centralised_only():
    with pytest.raises(PipelineError, match="cmpc"):
        MPCController(ControllerSpec("dmpc", coupling="nlp"), distributed=True)


@pytest.mark.parametrize(("mode", "iterations"), [("first_order", 2), ("exact", 1)])
def test_coupled_nlp_with_constant_velocity_matches_ibr(mode, iterations):
    # The same NLP in two formulations, so the same solver for both: IPOPT. From the first step's symmetric
    # zero start the rounding of the two formulations decides which of two local minima Fatrop reaches
    # (F = 26.36 or 23.31; each solver stays at either when started there); IPOPT's path does not.
    solver = ("solver", "ipopt")
    _, ibr = first_step(ControllerSpec("cmpc", mpc_overrides=(solver,)))
    _, nlp = first_step(
        ControllerSpec("cmpc", coupling="nlp", mpc_overrides=(("coupled_mode", mode), solver))
    )
    assert nlp.status == "ok" and nlp.iterations == iterations and nlp.extra["solves"] == ibr.extra["solves"]
    np.testing.assert_allclose(nlp.prediction, ibr.prediction, atol=1e-12)
    assert nlp.potential == pytest.approx(ibr.potential, rel=1e-4)


def test_forced_solver_failure_falls_back_and_the_episode_goes_on():
    spec = ControllerSpec("cmpc", mpc_overrides=(("solver_max_iter", 0),))
    controller = make_controller(spec)
    collect = Collect()
    env = CrowdEnv()
    obs = env.reset(0, "circle", 2)
    controller.reset(obs)
    for _ in range(3):
        out = controller.act(obs)
        assert out.fallback == "brake" and out.status == "Maximum_Iterations_Exceeded"
        obs, done, _ = env.step(out.accelerations)
        collect.outputs.append(out)
        assert not done
    np.testing.assert_allclose(collect.outputs[0].accelerations, 0.0)  # braking from rest


def test_a_dmpc_step_that_cannot_solve_applies_the_fallback_it_names():
    """With the heading start, a step whose every solve fails applies braking, as its label says, not the
    heading plan (a_max towards the goals, ignoring the humans)."""
    spec = ControllerSpec("dmpc", mpc_overrides=(("dmpc_start", "heading"), ("solver_max_iter", 0)))
    controller = MPCController(spec, distributed=True)
    obs = CrowdEnv().reset(0, "circle", 7, 3)
    controller.reset(obs)
    out = controller.act(obs)
    states = np.concatenate([obs.robot_positions, obs.robot_velocities], axis=1)
    cfg = controller.cfg
    assert out.fallback == "brake" and out.status == "Maximum_Iterations_Exceeded"
    np.testing.assert_array_equal(out.accelerations, braking(states, cfg.horizon, cfg.dt, cfg.a_max)[:, 0])
    controller.close()


def test_robot_on_its_goal_brakes_when_pinned():
    env = CrowdEnv()
    obs = env.reset(0, "circle", 3)
    velocities = obs.robot_velocities.copy()
    velocities[0] = [0.4, -0.6]
    obs = dataclasses.replace(obs, robot_velocities=velocities, robot_reached=np.array([True, False, False]))
    controller = make_controller(ControllerSpec("cmpc", mpc_overrides=(("on_goal", "brake"),)))
    controller.reset(obs)
    out = controller.act(obs)
    expected = braking(np.concatenate([obs.robot_positions, velocities], axis=1)[:1], 4, 0.4, 2.0)[0, 0]
    np.testing.assert_allclose(out.accelerations[0], expected, atol=1e-9)


@pytest.mark.parametrize("name", ["cmpc", "dmpc"])
def test_robot_on_its_goal_holds_position_when_tracking(name):
    """The default: a robot resting on its goal, nobody near, keeps still (its plan stays on the goal)."""
    env = CrowdEnv()
    obs = env.reset(0, "circle", 0)
    positions = obs.robot_positions.copy()
    positions[0] = obs.robot_goals[0]
    history = np.broadcast_to(positions, obs.history.shape)  # it has stood there (no humans)
    obs = dataclasses.replace(
        obs, robot_positions=positions, history=history, robot_reached=np.array([True, False, False])
    )
    controller = make_controller(ControllerSpec(name))
    controller.reset(obs)
    out = controller.act(obs)
    assert np.abs(out.accelerations[0]).max() < 1e-3
    assert np.linalg.norm(out.plan[0] - obs.robot_goals[0], axis=1).max() < 1e-3


@pytest.mark.parametrize("name", ["cmpc", "dmpc"])
def test_two_robots_without_humans_reach_their_goals(name):
    result = run_episode(
        make_controller(ControllerSpec(name)), seed=0, scenario="circle", n_humans=0, n_robots=2
    )
    assert result.metrics.success
    assert all(f is None for f in result.fallbacks)


def test_predictor_history_takes_the_last_rows_and_refuses_to_pad():
    env = CrowdEnv()
    obs = env.reset(0, "circle", 2)
    history, mask = predictor_history(obs, 3)
    assert history.shape == (3, 5, 2) and mask.all()
    np.testing.assert_array_equal(history, obs.history[-3:])
    full, _ = predictor_history(obs, len(obs.history))
    np.testing.assert_array_equal(full, obs.history)
    # the key a user sets: [env] refuses history_len ("set [world] obs_len")
    with pytest.raises(
        PipelineError, match=r"reads 10 observed steps.*holds 9 rows.*--set world\.obs_len=10\)$"
    ):
        predictor_history(obs, 10)
    # an observation built outside the simulator is told what its history needs, not only the simulator's key
    with pytest.raises(
        PipelineError, match=r"obs\.history holds 9 rows.*built outside the simulator needs 10"
    ):
        predictor_history(obs, 10)


def test_every_zoo_predictor_is_fed_exactly_its_observed_steps():
    """The default simulator keeps as many rows as every shipped model reads (Table I's L, as trained)."""
    from predictors.registry import available, load_predictor

    history_len = CrowdEnv().config.history_len
    for name in available():
        assert load_predictor(name).obs_len <= history_len, name


@pytest.mark.slow
@pytest.mark.parametrize("name", ["cmpc", "dmpc"])
def test_crowded_episodes_run_without_fallbacks(name):
    controller = make_controller(ControllerSpec(name))
    for seed in range(3):
        result = run_episode(controller, seed=seed, scenario="circle", n_humans=7)
        assert all(f is None for f in result.fallbacks)
        assert set(result.statuses) == {"ok"}
        assert result.metrics.n_steps == len(result.solve_times_s) > 0


def test_ibr_predicts_through_the_twin_and_matches_the_torch_rollout(monkeypatch):
    controller = make_controller(ControllerSpec("cmpc", "social_lstm_eth"))
    env = CrowdEnv()
    obs = env.reset(1, "perpendicular", 5)
    for _ in range(4):  # a few steps of history, the robots driving straight ahead
        obs, _, _ = env.step(np.tile([0.0, 0.5], (obs.n_robots, 1)))
    history, mask = predictor_history(obs, controller.model.obs_len)
    humans = np.arange(obs.n_robots, obs.n_robots + obs.n_humans)
    robots_future = obs.robot_positions + np.cumsum(np.full((4, obs.n_robots, 2), [0.1, 0.3]), axis=0)
    reference = controller.model.rollout(history, mask, robots_future, humans)

    def no_rollout(*args, **kwargs):
        raise AssertionError("the IBR loop called the torch rollout")

    monkeypatch.setattr(controller.model, "rollout", no_rollout)
    predict = controller._predict_fn(history, mask, humans)
    np.testing.assert_allclose(predict(robots_future), reference, rtol=0, atol=1e-9)
    # the robots' plan reaches the humans' prediction
    assert not np.allclose(predict(robots_future + 1.0), reference, atol=1e-6)


def test_the_mpc_is_built_from_the_simulators_world_and_refuses_to_disagree():
    from crowdsim.env_config import EnvConfig
    from crowdsim.world import WORLD, WorldFacts

    assert EnvConfig().world() == WORLD and EnvConfig.from_world(WORLD) == EnvConfig()
    fast = WorldFacts(v_max=1.5, a_max=3.0)
    controller = make_controller(ControllerSpec("cmpc"), EnvConfig.from_world(fast))
    assert (controller.cfg.v_max, controller.cfg.a_max, controller.cfg.dt) == (1.5, 3.0, 0.4)
    with pytest.raises(PipelineError, match=r"simulator's v_max is 1.5 but the MPC's is 1.0"):
        make_controller(ControllerSpec("cmpc", mpc_overrides=(("v_max", 1.0),)), EnvConfig.from_world(fast))
    with pytest.raises(PipelineError, match=r"predictor social_lstm_eth reads 9 .* keeps 5"):
        make_controller(ControllerSpec("cmpc", "social_lstm_eth"), EnvConfig(history_len=5))
    with pytest.raises(PipelineError, match=r"sampled every 0.4 s, the simulator's tau is 0.2 s"):
        make_controller(ControllerSpec("cmpc", "social_lstm_eth"), EnvConfig(dt=0.2))


@pytest.mark.parametrize(("name", "flocking"), [("cmpc", True), ("dmpc", False)])
def test_describe_states_coupling_flocking_and_distribution(name, flocking):
    """What a recording's "config" metadata says about the controller (and so what tells two runs apart)."""
    described = make_controller(ControllerSpec(name, flocking=flocking)).describe()
    config = described["config"]
    assert (config["coupling"], config["flocking"], config["distributed"]) == (
        "ibr",
        flocking,
        name == "dmpc",
    )
    assert (config["mpc"]["w_floc"] == 0.0) == (not flocking)  # NF: omega_floc = 0
    assert config["margins"] == {"mode": "none", "label": "none", "margins_m": []}
    assert described["predictor_sha256"] is None  # constant_velocity has no weights


def test_an_episode_of_another_time_step_is_refused():
    """A controller built for tau = 0.4 s must not drive a simulator stepping 0.2 s: its plans, predictions
    and bounds would all be off by a factor of two."""
    from crowdsim.env_config import EnvConfig

    controller = make_controller(ControllerSpec("cmpc"))
    obs = CrowdEnv(EnvConfig(dt=0.2)).reset(0, "circle", 2)
    with pytest.raises(
        PipelineError, match=r"obs.dt is 0.2 s \(the simulator.s step\) but the MPC plans with tau = 0.4 s"
    ):
        controller.reset(obs)


@pytest.mark.parametrize("name", ["cmpc", "dmpc"])
def test_act_before_reset_warns_once_per_controller_what_it_skips(name):
    """``act`` before any ``reset`` ran silently, and the layout warnings reset gives never came; a
    benchmark may time ``act`` alone, so it is said (once per controller), not refused."""
    obs = CrowdEnv().reset(0, "circle", 2)
    controller = make_controller(ControllerSpec(name))
    with pytest.warns(ActBeforeResetWarning) as record:
        controller.act(obs)
        controller.act(obs)
    said = [w for w in record if issubclass(w.category, ActBeforeResetWarning)]
    assert len(said) == 1 and said[0].filename == __file__  # the caller's line, not the controller's
    assert str(said[0].message) == (
        "MPCController.act called before reset: the checks reset makes on the robots' layout (FlockWarning, "
        "GoalRoomWarning) are skipped, and a size prepare() did not build is built inside this step; call "
        "reset(obs) at the start of each episode (said once per controller)"
    )
    with pytest.warns(ActBeforeResetWarning):  # another controller says it again
        make_controller(ControllerSpec(name)).act(obs)


def test_reset_then_act_says_nothing_of_a_missing_reset(recwarn):
    obs = CrowdEnv().reset(0, "circle", 2)
    controller = make_controller(ControllerSpec("cmpc"))
    controller.reset(obs)
    controller.act(obs)
    controller.reset(CrowdEnv().reset(1, "circle", 2))
    controller.act(obs)
    assert not [w for w in recwarn if issubclass(w.category, ActBeforeResetWarning)]


def test_a_hand_built_observation_is_checked_at_every_step():
    """Observations built outside the simulator (a tracker's) reach ``act`` without a ``reset`` in between:
    another time step was planned with at tau = 0.4 s, a one-robot ``robot_reached`` for two robots taken as
    both arrived (numpy's broadcasting), a velocity of the wrong shape failed in numpy's words, and a
    float32 history (9e-8 m of rounding) was refused as a history that is not the positions."""
    controller = make_controller(ControllerSpec("cmpc", predictor="constant_velocity"))
    obs = CrowdEnv().reset(0, "circle", 3, n_robots=2)
    controller.reset(obs)
    with pytest.raises(
        PipelineError, match=r"obs.dt is 0.1 s \(the simulator.s step\) but the MPC plans with tau = 0.4 s"
    ):
        controller.act(dataclasses.replace(obs, dt=0.1))
    wrong = {
        "robot_reached": (np.array([True]), "has shape (1,), expected (2,)"),
        "robot_velocities": (np.zeros(2), "has shape (2,), expected (2, 2)"),
        "human_positions": (np.zeros(3), "must be an (n, 2) array of positions in metres (np.zeros((0, 2)) "),
    }
    for field, (value, message) in wrong.items():
        with pytest.raises(PipelineError, match=rf"^obs.{field} {re.escape(message)}"):
            controller.act(dataclasses.replace(obs, **{field: value}))
    float32 = dataclasses.replace(obs, history=obs.history.astype(np.float32))
    assert controller.act(float32).status == "ok"
    # a tracker's map frame, a kilometre out: float32 rounds its positions by up to 6e-5 m there
    far = {f: getattr(obs, f) + 1234.5 for f in ("robot_positions", "human_positions")}
    check_history(dataclasses.replace(obs, **far, history=(obs.history + 1234.5).astype(np.float32)))
    with pytest.raises(PipelineError, match=r"obs.history\[-1\] \(now\) is not the agents' positions"):
        check_history(dataclasses.replace(obs, **far, history=(obs.history + 1234.6).astype(np.float32)))


def test_an_episode_does_not_depend_on_the_episodes_run_before():
    """Episode results are reproducible from (seed, scenario) alone: a controller reused across episodes
    starts each from a cold plan memory, as a fresh one does (a warm start from the last episode's plan
    changes the first solve)."""
    from crowdsim.env_config import EnvConfig

    short = EnvConfig(time_limit=2.0, timeout_margin=0.0)  # 5 control steps
    reused = make_controller(ControllerSpec("cmpc"), short)
    run_episode(reused, seed=0, scenario="circle", n_humans=3, env_config=short)
    again = run_episode(reused, seed=1, scenario="perpendicular", n_humans=3, env_config=short)
    fresh = run_episode(
        make_controller(ControllerSpec("cmpc"), short), seed=1, scenario="perpendicular", n_humans=3,
        env_config=short,
    )  # fmt: skip
    np.testing.assert_array_equal(again.robot_positions, fresh.robot_positions)


def test_an_error_the_predictor_raises_in_the_solve_is_no_solver_failure():
    """A RuntimeError of the predictor (a bug, a broken plugin net) propagates; only CasADi's own errors
    fall back (and would hide the bug behind braking robots)."""
    from predictors.constant_velocity import ConstantVelocity
    from predictors.errors import NoCasadiTwin

    class Failing(ConstantVelocity):
        def to_casadi(self, n_humans, n_robots, horizon):
            raise NoCasadiTwin("none here")  # so that the IBR loop calls rollout

        def rollout(self, *args, **kwargs):
            raise RuntimeError("the predictor broke")

    controller = MPCController(ControllerSpec("cmpc"), False, predictor=Failing())
    obs = CrowdEnv().reset(0, "circle", 3)
    controller.reset(obs)
    with pytest.raises(RuntimeError, match="the predictor broke"):
        controller.act(obs)


def test_describe_names_the_weights_of_a_trained_predictor():
    """A record names the checkpoint it planned with, so that a retrained model's runs never mix with it."""
    from predictors.registry import checkpoint_sha256

    sha256 = make_controller(ControllerSpec("cmpc", "social_lstm_eth")).describe()["predictor_sha256"]
    assert sha256 == checkpoint_sha256("social_lstm_eth") and len(sha256) == 64


def test_the_records_name_the_weights_loaded_when_the_zoo_entry_is_replaced_meanwhile(monkeypatch):
    """describe() looked the name up in the zoo at every episode: after `crowdmpc zoo add ... --replace` of
    the name during a run, the controller still planned with the weights it had loaded, and its episodes were
    recorded under the new weights' sha256 (their runs mixed, which the sha256 is there to prevent)."""
    import pipelines.loop.mpc
    from predictors.registry import checkpoint_sha256

    controller = make_controller(ControllerSpec("cmpc", "social_lstm_eth"))
    loaded = checkpoint_sha256("social_lstm_eth")
    monkeypatch.setattr(pipelines.loop.mpc, "loaded_sha256", lambda model: "f" * 64)  # replaced
    assert controller.describe()["predictor_sha256"] == loaded
    result = run_episode(controller, seed=0, scenario="circle", n_humans=1)
    assert result.predictor_sha256 == loaded


def test_close_stops_the_dmpc_solver_threads():
    """run_episodes closes its controller; DMPC's worker threads must end with it (a sweep worker builds a
    controller per cell and would otherwise keep every cell's threads alive)."""
    spec = ControllerSpec("dmpc", mpc_overrides=(("dmpc_parallel", "threads"),))
    controller = make_controller(spec)
    obs = CrowdEnv().reset(0, "circle", 2)
    controller.reset(obs)
    controller.act(obs)
    solver = controller.solver(obs.n_robots, obs.n_humans)
    assert solver._pool is not None  # the threads the step used
    controller.close()
    assert solver._pool is None


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (lambda o: {"history": o.history[:, :-1]}, r"obs\.history has shape \(9, 6, 2\).*\(L, 7, 2\)"),
        (lambda o: {"history": o.history[:, :, :1]}, r"obs\.history has shape \(9, 7, 1\)"),
        (lambda o: {"history": o.history[-1]}, r"obs\.history has shape \(7, 2\)"),
        (lambda o: {"history": o.history + 1.0}, r"obs\.history\[-1\].*robot 0.*robot_positions"),
        (
            lambda o: {"human_positions": o.human_positions + np.array([[0.0, 0.0]] * 3 + [[0.0, 0.5]])},
            r"obs\.history\[-1\].*human 3.*human_positions",
        ),
        (
            lambda o: {"human_positions": np.where(np.arange(4)[:, None] == 1, np.nan, o.human_positions)},
            r"obs\.human_positions holds a position that is not finite \(human 1 at \[nan, nan\]\)",
        ),
    ],
)
def test_a_hand_built_observation_whose_history_disagrees_with_it_is_refused(change, match):
    """An observation built outside the simulator (a tracker on a real robot): the predictor reads
    ``history``, the MPC ``robot_positions``; a history with a column too few or too many (a human who left,
    kept) or whose row "now" is not the positions (a stale or reordered history) was planned with silently,
    or failed deep in the predictor ("could not broadcast (544,) into (477,)")."""
    env = CrowdEnv()
    obs = env.reset(0, "circle", 4)
    controller = make_controller(ControllerSpec("cmpc"))
    controller.reset(obs)
    bad = dataclasses.replace(obs, **change(obs))
    with pytest.raises(PipelineError, match=match):
        controller.reset(bad)
    with pytest.raises(PipelineError, match=match):
        controller.act(bad)


@pytest.mark.parametrize("controller", ["cmpc", "dmpc"])
def test_a_team_of_no_robots_is_braked_without_a_solver(controller):
    """CMPC took an observation of no robots (act returns no rows); DMPC's reset built a local NLP of size 0
    and raised CasADi's assertion "Dimensions must be non-negative, got -1-by-1"."""
    obs = CrowdEnv().reset(0, "circle", 3, 0)
    policy = make_controller(ControllerSpec(controller))
    try:
        policy.reset(obs)
        assert policy.act(obs).accelerations.shape == (0, 2)
    finally:
        policy.close()
