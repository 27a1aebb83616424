"""The closed loop's functions as a notebook calls them: results that compare, numpy counts, and arguments of
the wrong kind named in one line before any episode runs (each failed deep inside, or after an episode)."""

from __future__ import annotations

import copy
import dataclasses
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from pipelines.errors import PipelineError
from pipelines.loop.controllers import ControllerSpec, make_controller
from pipelines.loop.episode import run_episode, run_episodes

ORCA = ControllerSpec("orca")
ROOT = Path(__file__).resolve().parents[2]


def test_episodes_compare_by_value_and_a_numpy_seed_is_a_python_int():
    """`a == b` raised numpy's "truth value of an array ... is ambiguous"; a numpy seed stayed numpy's (and
    np.uint64's largest wrapped round to seed 0 for the next episode)."""
    first, second = run_episodes(
        ORCA, episodes=2, seed=np.int64(3), scenario="circle", n_humans=2, progress=False
    )
    again = run_episodes(ORCA, episodes=1, seed=3, scenario="circle", n_humans=2, progress=False)[0]
    assert type(first.seed) is int and (first.seed, second.seed) == (3, 4)
    assert first == copy.deepcopy(first) and first != second
    assert first == again  # a seed repeats all but the steps' wall times, which are not compared
    # NaN in a tuple (reach_times of a robot that never arrived) equals itself, through a pickle too
    import pickle

    late = dataclasses.replace(first.metrics, reach_times=(float("nan"), 1.0))
    cut = dataclasses.replace(first, metrics=late)
    assert cut == pickle.loads(pickle.dumps(cut)) and cut != first


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        ({"env_config": None}, "run_episode: env_config must be an EnvConfig, got None"),
        ({"observers": None}, "run_episode: observers must be a sequence of EpisodeObservers, got None"),
        ({"observers": [object()]}, "run_episode: observer <object object at "),
    ],
)
def test_run_episode_names_an_argument_of_the_wrong_kind(arguments, message):
    controller = make_controller(ORCA)
    with pytest.raises(PipelineError, match="^" + message.replace("(", r"\(")):
        run_episode(controller, seed=0, scenario="circle", n_humans=1, **arguments)


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        ({"into": ()}, "run_episodes: into must be a list the results are appended to, got ()"),
        (
            {"observers_factory": []},
            "run_episodes: observers_factory must be a function returning each episode's observers (e.g. "
            "lambda: [recorder]), got []",
        ),
    ],
)
def test_run_episodes_names_into_and_the_observers_factory_before_any_episode(
    arguments, message, monkeypatch
):
    """A tuple as `into` failed after the first episode, its result lost; a list as the factory at it."""
    monkeypatch.setattr("pipelines.loop.episode.make_controller", None)  # nothing may be built first
    with pytest.raises(PipelineError) as refused:
        run_episodes(ORCA, episodes=1, seed=0, scenario="circle", n_humans=1, progress=False, **arguments)
    assert str(refused.value) == message


@pytest.mark.parametrize("margins", ["none", "conformal"])
@pytest.mark.parametrize("sensor_range", [-1.0, 0, float("inf"), float("nan"), "2", True])
def test_run_episodes_names_a_sensor_range_that_is_no_distance_before_the_build(
    sensor_range, margins, monkeypatch
):
    """It was refused after the controller was built, as RangeLimited's "sensor radius", or with calibrated
    margins as the "margins' sensor_range" before that; inf ran without margins and was refused with them."""
    from pipelines.loop.margins import parse_margins

    monkeypatch.setattr("pipelines.loop.episode.make_controller", None)  # nothing may be built first
    spec = ControllerSpec("cmpc", margins=parse_margins(margins))
    with pytest.raises(PipelineError) as refused:
        run_episodes(
            spec, episodes=1, seed=0, scenario="circle", n_humans=1, progress=False, sensor_range=sensor_range
        )
    assert str(refused.value) == (
        "run_episodes: sensor_range must be a finite number of metres > 0 (None: every human seen), got "
        f"{sensor_range!r}"
    )


def test_run_episodes_takes_a_numpy_sensor_range():
    results = run_episodes(
        ORCA, episodes=1, seed=0, scenario="circle", n_humans=1, progress=False, sensor_range=np.int64(3)
    )
    assert len(results) == 1


def test_read_recording_names_a_path_and_topics_of_the_wrong_kind(tmp_path):
    """`topics="/episode/metrics"` was iterated into its characters and read nothing, silently; None as the
    path was pathlib's TypeError."""
    from pipelines.logs.reader import read_recording

    with pytest.raises(PipelineError, match=r"^read_recording takes a path to an MCAP file, got None$"):
        read_recording(None)  # type: ignore[arg-type]
    with pytest.raises(PipelineError) as refused:
        read_recording(tmp_path / "x.mcap", topics="/episode/metrics")
    assert str(refused.value) == (
        "topics must be a list of topics, e.g. ['/episode/metrics'], got the string itself"
    )


def test_the_mpc_plans_without_the_humans_velocities_which_orca_needs():
    """The MPC never reads them (a tracker may give none); ORCA avoids the humans by them."""
    from crowdsim.env import CrowdEnv

    obs = CrowdEnv().reset(0, "circle", 3)
    unknown = dataclasses.replace(obs, human_velocities=np.full((3, 2), np.nan))
    mpc = make_controller(ControllerSpec("cmpc"))
    mpc.reset(unknown)
    assert np.isfinite(mpc.act(unknown).accelerations).all()
    orca = make_controller(ORCA)
    orca.reset(obs)
    with pytest.raises(
        PipelineError, match=r"^obs.human_velocities holds a value that is not finite \(row 0"
    ):
        orca.act(unknown)


@pytest.mark.parametrize("controller", ["orca", "straight", "cmpc"])
@pytest.mark.parametrize(
    ("field", "message"),
    [
        (
            "human_positions",
            "obs.human_positions holds a position that is not finite (human 1 at [nan, nan])",
        ),
        ("robot_velocities", "obs.robot_velocities holds a value that is not finite (row 1: [nan, nan])"),
        ("robot_goals", "obs.robot_goals holds a value that is not finite (row 1: [nan, nan])"),
    ],
)
def test_every_shipped_controller_refuses_a_state_that_is_not_finite(controller, field, message):
    """ORCA and the straight line returned NaN accelerations (or planned around NaN humans as if absent);
    the MPC's NaN velocities failed as "states must be finite rows ... of shape (M, 4), got shape (3, 4)"."""
    from crowdsim.env import CrowdEnv

    obs = CrowdEnv().reset(0, "circle", 3)
    built = make_controller(ControllerSpec(controller))
    built.reset(obs)
    values = np.array(getattr(obs, field), dtype=float)
    values[1] = np.nan
    with pytest.raises(PipelineError) as refused:
        built.act(dataclasses.replace(obs, **{field: values}))
    assert str(refused.value).startswith(message)


HUGE = """
import dataclasses, sys
sys.path.insert(0, {root!r})
import numpy as np
from crowdsim.env import CrowdEnv
from pipelines.errors import PipelineError
from pipelines.loop.controllers import ControllerSpec, make_controller
obs = CrowdEnv().reset(0, "circle", 3)
velocities = np.array(obs.robot_velocities, dtype=float)
velocities[1, 0] = 1e200
humans = np.array(obs.human_positions, dtype=float)
humans[2] = -1e308
history = np.array(obs.history, dtype=float)
history[-1, obs.n_robots + 2] = -1e308
for name in ("cmpc", "dmpc"):
    controller = make_controller(ControllerSpec(name))
    controller.reset(obs)
    for bad in (
        dataclasses.replace(obs, robot_velocities=velocities),
        dataclasses.replace(obs, human_positions=humans, history=history),
    ):
        try:
            controller.act(bad)
        except PipelineError as exc:
            print(exc)
"""


def test_the_mpc_refuses_finite_but_absurd_numbers_in_one_line():
    """A hand-built observation with a robot velocity of 1e200 (or a human at -1e308) made the NLP's
    gradient NaN, and the step's first Fatrop solve never returned; in a process of its own, under a time
    limit, for that reason."""
    done = subprocess.run(
        [sys.executable, "-c", HUGE.format(root=str(ROOT))], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    tail = "the most the MPC plans with; far larger ones overflow its arithmetic"
    velocity = (
        f"obs.robot_velocities holds a number beyond 1e+09 m/s in magnitude (row 1: [1e+200, 0.0]), {tail}"
    )
    human = (
        f"obs.human_positions holds a number beyond 1e+09 m in magnitude (row 2: [-1e+308, -1e+308]), {tail}"
    )
    assert done.stdout.splitlines() == [velocity, human] * 2


PAST = """
import dataclasses, sys
sys.path.insert(0, {root!r})
import numpy as np
from crowdsim.env import CrowdEnv
from pipelines.errors import PipelineError
from pipelines.loop.controllers import ControllerSpec, make_controller
obs = CrowdEnv().reset(0, "circle", 3)
history = np.array(obs.history, dtype=float)
history[-2, obs.n_robots + 1] = 1e307
controller = make_controller(ControllerSpec("cmpc", predictor="constant_velocity", coupling="nlp"))
controller.reset(obs)
try:
    controller.act(dataclasses.replace(obs, history=history))
except PipelineError as exc:
    print(exc)
"""


def test_the_mpc_refuses_an_absurd_number_in_the_history_in_one_line():
    """A human at 1e307 a step before the current one, which only the history holds: the coupled NLP's
    constant-velocity prediction ran that human to 1e308, and its Fatrop solve never returned (in a process
    of its own, under a time limit, for that reason)."""
    done = subprocess.run(
        [sys.executable, "-c", PAST.format(root=str(ROOT))], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines() == [
        "obs.history holds a number beyond 1e+09 m in magnitude (human 1 at row -2: [1e+307, 1e+307]), the "
        "most the MPC plans with; far larger ones overflow its arithmetic"
    ]


def test_small_things_a_notebook_does_with_the_mpc_and_the_registry():
    """A controller copied or pickled failed with "cannot pickle 'SwigPyObject'"; margins as a numpy array
    were refused as "must be a sequence of 4 numbers, got array([...])"; a list of predictors was
    "unhashable type: 'list'"."""
    import copy
    import pickle

    from mpc.config import MPCConfig
    from predictors.errors import UnknownPredictor
    from predictors.registry import load_predictor

    controller = make_controller(ControllerSpec("dmpc"))
    for copied in (copy.deepcopy, pickle.dumps):
        with pytest.raises(
            PipelineError, match=r"^MPCController holds built CasADi solvers, which cannot be"
        ):
            copied(controller)
    assert pickle.loads(pickle.dumps(ControllerSpec("dmpc"))) == ControllerSpec("dmpc")
    assert MPCConfig(human_margins=np.array([0.1, 0.2, 0.3, 0.4])).human_margins == (0.1, 0.2, 0.3, 0.4)
    from mpc.config import MPCConfigError

    with pytest.raises(MPCConfigError, match="^human_margins must be a sequence of 4 numbers"):
        MPCConfig(human_margins=np.array(0.1))
    with pytest.raises(UnknownPredictor, match=r"^unknown predictor \['social_lstm_eth'\]; choose from"):
        load_predictor(["social_lstm_eth"])  # type: ignore[arg-type]


def test_an_experiment_and_a_sweep_config_built_by_hand_are_checked_before_any_work(tmp_path):
    """Each failed deep inside (a str as a spec, an int as humans, a float as a count), or ran with every
    episode in errors.jsonl (99 humans, seed 1.5), leaving a sweep folder behind."""
    from pathlib import Path

    from pipelines.experiments.cells import Experiment
    from pipelines.experiments.sweep_config import SweepConfig

    def experiment(**changes):
        values = {"name": "mine", "title": "t", "methods": (("ORCA", ORCA),), "humans": (2,)} | changes
        return Experiment(**values)

    for changes, message in (
        ({"methods": (("ORCA", "orca"),)}, "methods must be (label, ControllerSpec) pairs"),
        ({"methods": {"ORCA": ORCA}}, "methods must be (label, ControllerSpec) pairs"),
        ({"humans": 2}, "humans must be numbers of humans in 1..50, got 2"),
        ({"humans": (99,)}, "humans must be numbers of humans in 1..50, got (99,)"),
        ({"method_robots": {"nope": 2}}, "method_robots names no method: ['nope']"),
    ):
        with pytest.raises(PipelineError) as refused:
            experiment(**changes)
        assert str(refused.value).startswith(f"experiment 'mine': {message}")
    for arguments, message in (
        ({"episodes_per_cell": 1.5}, "SweepConfig's episodes_per_cell must be an int, got 1.5"),
        ({"seed": 1.5}, "SweepConfig's seed must be an int, got 1.5"),
        ({"n_robots": 2.0}, "SweepConfig's n_robots must be an int, got 2.0"),
    ):
        with pytest.raises(PipelineError) as refused:
            SweepConfig(
                **({"experiment": experiment(), "out": Path(tmp_path), "episodes_per_cell": 1} | arguments)
            )
        assert str(refused.value) == message
    assert SweepConfig(experiment(), tmp_path, np.int64(2)).episodes_per_cell == 2
    assert experiment(humans=tuple(np.arange(5, 7))).humans == (5, 6)  # numpy's counts, kept as ints
    with pytest.raises(PipelineError, match=r"^--humans must list numbers of humans, got \(5.5,\)$"):
        SweepConfig(experiment(), tmp_path, 1, humans=(5.5,))  # type: ignore[arg-type]
    with pytest.raises(PipelineError, match=r"^--humans must list numbers of humans, got 5$"):
        SweepConfig(experiment(), tmp_path, 1, humans=5)  # type: ignore[arg-type]
    with pytest.raises(PipelineError, match=r"^SweepConfig's out must be a folder's path, got None$"):
        SweepConfig(experiment(), None, 1)  # type: ignore[arg-type]
    assert SweepConfig(experiment(), tmp_path, 1, humans=np.arange(5, 7)).humans == (5, 6)  # type: ignore[arg-type]
    assert list(tmp_path.iterdir()) == []
