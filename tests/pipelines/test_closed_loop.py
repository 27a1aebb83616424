"""The closed loop: episode bookkeeping, observer hooks, seeds, summaries, errors that must surface."""

import re

import numpy as np
import pytest

from crowdsim.env_config import EnvConfig
from crowdsim.errors import SimulationError
from pipelines.errors import PipelineError
from pipelines.loop.controllers import ControllerSpec, ControlOutput, make_controller
from pipelines.loop.episode import run_episode, run_episodes, summarize


class Spy:
    """An EpisodeObserver that records the calls it gets."""

    def __init__(self):
        self.calls = []
        self.meta = None
        self.result = None

    def on_reset(self, obs, meta):
        self.calls.append(("reset", obs.step))
        self.meta = meta

    def on_step(self, obs, out, next_obs):
        assert next_obs.step == obs.step + 1
        self.calls.append(("step", obs.step))

    def on_end(self, result):
        self.calls.append(("end", None))
        self.result = result


def test_run_episode_records_everything_and_calls_the_hooks_in_order():
    spy = Spy()
    result = run_episode(
        make_controller(ControllerSpec("orca")), seed=3, scenario="circle", n_humans=5, observers=[spy]
    )
    t = result.metrics.n_steps
    assert result.robot_positions.shape == (t + 1, 3, 2) and result.human_positions.shape == (t + 1, 5, 2)
    assert (
        result.solve_times_s.shape == (t,) and len(result.statuses) == t and result.iterations.shape == (t,)
    )
    assert result.controller == "orca" and result.predictor is None and result.seed == 3
    assert spy.calls == [("reset", 0)] + [("step", k) for k in range(t)] + [("end", None)]
    assert spy.result is result
    assert {"seed", "scenario", "controller", "predictor", "predictor_sha256", "config"} <= set(spy.meta)
    assert spy.meta["config"]["env"]["dt"] == 0.4 and spy.meta["config"]["env"]["orca"]["time_horizon"] == 5.0


def test_run_episodes_uses_seed_plus_i_and_fresh_observers():
    made = []

    def factory():
        made.append(Spy())
        return [made[-1]]

    results = run_episodes(
        ControllerSpec("straight"), episodes=3, seed=10, scenario="perpendicular", n_humans=4, n_robots=2,
        observers_factory=factory, progress=False,
    )  # fmt: skip
    assert [r.seed for r in results] == [10, 11, 12] and len(made) == 3
    single = run_episode(
        make_controller(ControllerSpec("straight")), seed=11, scenario="perpendicular", n_humans=4, n_robots=2
    )
    np.testing.assert_array_equal(single.human_positions, results[1].human_positions)
    assert made[1].meta["seed"] == 11


def test_summarize_reports_rates_and_step_costs():
    results = run_episodes(
        ControllerSpec("orca"), episodes=2, seed=0, scenario="circle", n_humans=3, progress=False
    )
    s = summarize(results)
    assert s["episodes"] == 2 and 0 <= s["success_rate"] <= 100
    assert s["control_steps"] == sum(r.metrics.n_steps for r in results)
    assert 0 < s["solve_time_median_ms"] <= s["solve_time_p95_ms"] <= s["solve_time_max_ms"]
    assert (
        s["iterations_max"] == 0 and s["fallback_steps"] == 0 and s["statuses"] == {"ok": s["control_steps"]}
    )


def test_controller_errors_are_not_swallowed():
    class Broken:
        name = "broken"
        predictor = None

        def reset(self, obs):
            pass

        def describe(self):
            return {}

        def close(self):
            pass

        def act(self, obs):
            if obs.step == 2:
                raise RuntimeError("solver exploded")
            return ControlOutput(accelerations=np.zeros((obs.n_robots, 2)))

    # a controller from outside the package, as a plugin: one line naming it, its exception the cause
    with pytest.raises(PipelineError, match=r"act\(\) raised RuntimeError: solver exploded") as caught:
        run_episode(Broken(), seed=0, scenario="circle", n_humans=2)
    assert isinstance(caught.value.__cause__, RuntimeError)


def test_env_config_is_used():
    result = run_episode(
        make_controller(ControllerSpec("orca")), seed=0, scenario="circle", n_humans=2,
        env_config=EnvConfig(time_limit=2.0, timeout_margin=0.0),
    )  # fmt: skip
    assert result.metrics.n_steps == 5 and result.metrics.timeout


def test_the_baselines_drive_within_the_simulators_bounds_and_orca_setup():
    """ORCA and the straight line are built for env_config, as the MPC is (its world()): the robot bounds,
    and for ORCA the humans' parameters and radius margin; the defaults without one."""
    from crowdsim.env import CrowdEnv
    from crowdsim.orca import OrcaParams

    env_config = EnvConfig(v_max=0.5, a_max=1.0, orca=OrcaParams(time_horizon=2.0), orca_radius_margin=0.05)
    orca, straight = (make_controller(ControllerSpec(c), env_config).inner for c in ("orca", "straight"))
    assert (orca.v_max, orca.a_max, orca.params, orca.radius_margin) == (0.5, 1.0, env_config.orca, 0.05)
    assert (straight.v_max, straight.a_max) == (0.5, 1.0)
    paper = make_controller(ControllerSpec("orca")).inner
    assert (paper.v_max, paper.a_max, paper.params, paper.radius_margin) == (1.0, 2.0, OrcaParams(), 0.01)
    # From rest, ORCA asks for up to v_max / tau = 1.25 m/s^2 towards the goal: clipped to the env's a_max.
    obs = CrowdEnv(env_config).reset(0, "circle", 5)
    out = make_controller(ControllerSpec("orca"), env_config).act(obs)
    assert np.abs(out.accelerations).max() == pytest.approx(1.0)


def test_every_controller_name_has_its_facts_and_a_builder_and_states_its_predictor():
    from typing import get_args

    from pipelines.loop.controllers import CONTROLLER_KINDS, CONTROLLERS, ControllerName

    assert set(CONTROLLERS) == set(CONTROLLER_KINDS) == set(get_args(ControllerName))
    for name, kind in CONTROLLER_KINDS.items():
        spec = ControllerSpec(name, "constant_velocity")
        controller = make_controller(spec)
        try:
            assert controller.predictor == spec.predictor_name
            assert (controller.predictor is not None) == kind.uses_predictor
            assert set(controller.describe()) >= {"predictor_sha256", "config"}
        finally:
            controller.close()


class Scripted:
    """A controller that stands still, says what it plans with, and notes what the loop calls."""

    name = "scripted"
    predictor = "constant_velocity"

    def __init__(self, iterations=0, fallback=None):
        self.calls = []
        self.iterations, self.fallback = iterations, fallback

    def reset(self, obs):
        self.calls.append(("reset", obs.step))

    def describe(self):
        return {"predictor_sha256": "abc123", "config": {"mpc": {"horizon": 4}}, "note": "described"}

    def close(self):
        self.calls.append(("close", None))

    def act(self, obs):
        self.calls.append(("act", obs.step))
        return ControlOutput(
            accelerations=np.zeros((obs.n_robots, 2)), iterations=self.iterations, fallback=self.fallback
        )


def test_meta_precedence_defaults_then_describe_then_the_callers():
    """A caller's meta (the CLI's run config) has the last word over what the controller describes, which
    has it over the loop's defaults; the described sha256 is the result's too (a recording names the weights
    it ran with). The controller is reset with the first observation before it acts."""
    spy, controller = Spy(), Scripted()
    result = run_episode(
        controller, seed=1, scenario="circle", n_humans=2, observers=[spy],
        env_config=EnvConfig(time_limit=1.2, timeout_margin=0.0), meta={"note": "caller's", "extra": 1},
    )  # fmt: skip
    assert (spy.meta["note"], spy.meta["extra"], spy.meta["predictor_sha256"]) == ("caller's", 1, "abc123")
    assert spy.meta["config"]["mpc"] == {"horizon": 4} and "env" in spy.meta["config"]
    assert (result.predictor, result.predictor_sha256) == ("constant_velocity", "abc123")
    # 1.2 s of 0.4 s steps, no margin: steps at t = 0, 0.4, 0.8
    assert controller.calls == [("reset", 0), ("act", 0), ("act", 1), ("act", 2)]


def test_a_callers_meta_may_not_relabel_the_episode():
    """run_episodes hands every episode the same meta: a seed there named every recording alike."""
    with pytest.raises(PipelineError, match=r"run_episode: meta must not set \['seed', 'config'\]"):
        run_episode(Scripted(), seed=1, scenario="circle", n_humans=2, meta={"seed": 0, "config": {}})


def test_run_episodes_closes_its_controller_even_when_an_episode_raises(monkeypatch):
    controller = Scripted()
    monkeypatch.setattr("pipelines.loop.episode.make_controller", lambda spec, env, read=None: controller)

    def broken_observers():
        raise RuntimeError("observer factory broke")

    with pytest.raises(RuntimeError, match="observer factory broke"):
        run_episodes(
            ControllerSpec("orca"), episodes=2, seed=0, scenario="circle", n_humans=2,
            observers_factory=broken_observers, progress=False,
        )  # fmt: skip
    assert controller.calls == [("close", None)]


def test_summarize_counts_iterations_and_fallbacks_over_every_episode():
    short = EnvConfig(time_limit=1.2, timeout_margin=0.0)  # 3 control steps an episode
    first = run_episode(Scripted(iterations=1), seed=0, scenario="circle", n_humans=2, env_config=short)
    second = run_episode(
        Scripted(iterations=4, fallback="brake"), seed=1, scenario="circle", n_humans=2, env_config=short
    )
    s = summarize([first, second])
    # iterations 1, 1, 1, 4, 4, 4: mean 15 / 6 = 2.5, max 4; the second episode's 3 steps fell back
    assert (s["control_steps"], s["iterations_mean"], s["iterations_max"]) == (6, 2.5, 4)
    assert s["fallback_steps"] == 3
    s = summarize([second, first])  # the fallbacks counted wherever they are
    assert s["fallback_steps"] == 3


@pytest.mark.parametrize("controller", ["orca", "dmpc"])
def test_an_episode_without_robots_is_refused_before_it_starts(controller):
    """``run_episode(..., n_robots=0)``: ORCA and CMPC ran the whole episode (29 steps, observers and all)
    and then failed in the metrics ("need at least one robot"); DMPC failed in CasADi ("Dimensions must be
    non-negative, got -1-by-1"). The simulator takes crowds without robots (its check says "n_robots must
    be in [0, 12]"); an episode's record is the robots'."""
    from crowdsim.errors import SimulationError

    spy = Spy()
    with pytest.raises(SimulationError, match=r"^run_episode: n_robots must be in \[1, 12\], got 0$"):
        run_episode(make_controller(ControllerSpec(controller)), seed=0, scenario="circle", n_humans=3,
                    n_robots=0, observers=[spy])  # fmt: skip
    assert spy.calls == []


@pytest.mark.parametrize(
    "changes, message",
    [
        ({"seed": "0"}, "run_episodes: seed must be an int >= 0, got '0'"),
        ({"seed": None}, "run_episodes: seed must be an int >= 0, got None"),
        ({"seed": True}, "run_episodes: seed must be an int >= 0, got True"),  # it ran seed 1
        ({"env_config": {"dt": 0.4}}, "run_episodes: env_config must be an EnvConfig, got {'dt': 0.4}"),
        ({"n_robots": 13}, "run_episodes: n_robots must be in [1, 12], got 13"),  # it said [0, 12]
        ({"scenario": "square", "episodes": 0}, "unknown scenario 'square'"),  # checked with none to run too
    ],
)
def test_run_episodes_names_a_bad_argument_before_building_anything(changes, message, monkeypatch):
    """From a notebook: seed "0" or None failed at ``seed + i`` with Python's TypeError, an env_config dict
    with "'dict' object has no attribute 'world'", both after the controller was built."""
    import pipelines.loop.episode as episode

    monkeypatch.setattr(episode, "make_controller", lambda *a, **k: pytest.fail("built before the check"))
    arguments = {"episodes": 1, "seed": 0, "scenario": "circle", "n_humans": 2, "progress": False}
    with pytest.raises((PipelineError, SimulationError)) as raised:
        run_episodes(ControllerSpec("straight"), **{**arguments, **changes})
    assert str(raised.value) == message or str(raised.value).startswith(message)
    monkeypatch.undo()
    assert run_episodes(ControllerSpec("straight"), **{**arguments, "seed": np.int64(3), "episodes": 0}) == []


def test_an_episode_result_shows_itself_in_one_line():
    """A notebook cell ending in ``run_episode(...)`` (or a list of results) printed every position of every
    agent at every step, every solve time and status: 30 kB and 860 lines for one CMPC episode of 7 humans.
    The repr keeps what the episode was and its metrics; the trajectories stay attributes."""
    result = run_episode(make_controller(ControllerSpec("orca")), seed=3, scenario="circle", n_humans=5)
    text = repr(result)
    assert "\n" not in text and len(text) < 1500
    start = "EpisodeResult(seed=3, scenario='circle', n_humans=5, n_robots=3, controller='orca', predictor="
    assert text.startswith(start)
    assert repr(result.metrics) in text


def test_a_spec_where_a_controller_goes_and_the_other_way_round_are_named():
    """In a notebook, ``run_episode(ControllerSpec("cmpc"), ...)`` ended in "AttributeError: 'ControllerSpec'
    object has no attribute 'name'", and ``run_episodes("cmpc", ...)`` in "'str' object has no attribute
    'controller'"; ``episodes=-1`` ran nothing without a word and ``episodes=2.5`` was a TypeError of
    range(). Each is a PipelineError saying what the function takes."""
    kwargs = {"seed": 0, "scenario": "circle", "n_humans": 3}
    with pytest.raises(PipelineError, match=r"^run_episode takes a controller built by make_controller"):
        run_episode(ControllerSpec("cmpc"), **kwargs)
    with pytest.raises(PipelineError, match=r"^run_episode: 'cmpc' is no controller: it has no reset, act"):
        run_episode("cmpc", **kwargs)
    with pytest.raises(PipelineError, match=r"^run_episodes takes a ControllerSpec .*, got 'cmpc'$"):
        run_episodes("cmpc", episodes=1, progress=False, **kwargs)
    for episodes in (-1, 2.5, True):
        with pytest.raises(PipelineError, match=r"^run_episodes: episodes must be an int >= 0, got "):
            run_episodes(ControllerSpec("orca"), episodes=episodes, progress=False, **kwargs)
    assert run_episodes(ControllerSpec("orca"), episodes=0, progress=False, **kwargs) == []
    assert len(run_episodes(ControllerSpec("orca"), episodes=np.int64(1), progress=False, **kwargs)) == 1


def test_the_progress_bar_shows_the_running_episodes_step(monkeypatch, capsys):
    """A bar of episodes sat at 0 of 1 through an episode of minutes (a long horizon) as if hung."""
    import predictors.progress
    from pipelines.loop import episode

    monkeypatch.setattr(
        episode, "progress_bar", lambda *a, **k: predictors.progress.progress_bar(*a, **k, mininterval=0)
    )
    monkeypatch.setattr(episode.StepShown, "every", 0.0)
    results = episode.run_episodes(
        ControllerSpec("straight"), episodes=2, seed=0, scenario="circle", n_humans=2, progress=True
    )
    err = capsys.readouterr().err
    steps = results[0].metrics.n_steps
    assert "0/2 [" in err and f"step={steps}]" in err  # the first episode's last step, before it counts
    assert f"success={100 * results[0].metrics.success:.0f}%, step=1]" in err  # then the second's first
    quiet = episode.run_episodes(
        ControllerSpec("straight"), episodes=1, seed=0, scenario="circle", n_humans=2, progress=False
    )
    assert capsys.readouterr().err == "" and quiet[0].metrics == results[0].metrics


@pytest.mark.parametrize(
    "spec, env_config, message",
    [
        ("cmpc", None, "make_controller takes a ControllerSpec (ControllerSpec('cmpc')), got 'cmpc'"),
        (ControllerSpec("orca"), {"a_max": 1.0}, "env_config must be an EnvConfig or None,"),
    ],
)
def test_make_controller_names_a_name_or_a_dict_given_in_place_of_its_arguments(spec, env_config, message):
    # each failed on an attribute deep inside: AttributeError: 'str' object has no attribute 'controller'
    with pytest.raises(PipelineError, match=re.escape(message)):
        make_controller(spec, env_config)


@pytest.mark.parametrize("name, predictor", [(5, None), ("", None), ("mine", 3)])
def test_a_hand_built_controller_names_itself_with_strings(name, predictor):
    """The records and recordings write a controller's ``name`` and ``predictor`` as strings (their schemas):
    a hand-built controller with ``name = 5`` ran, and its recording's /episode/metrics message was refused
    by ``review --check`` ("$.controller: expected string, got int 5"). It is refused before the reset."""
    from pipelines.loop.baselines import orca

    controller = orca()
    controller.name, controller.predictor = name, predictor  # type: ignore[misc]
    with pytest.raises(PipelineError, match=r"^run_episode: a controller needs a non-empty str name and a "):
        run_episode(controller, seed=0, scenario="circle", n_humans=1, n_robots=1)
