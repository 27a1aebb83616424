"""conformal-motion margins: parsing, resolution from a calibration with class margins, per-human margins in
the controller's step."""

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest

from pipelines.errors import PipelineError
from pipelines.loop.controllers import ControllerSpec, make_controller
from pipelines.loop.margins import MarginSpec, parse_margins
from predictors.calibration_store import save_calibration
from tests.calibration_blocks import class_errors, constant_velocity_block


def test_parse_and_label():
    assert parse_margins("conformal-motion") == MarginSpec("conformal-motion", alpha=0.1)
    assert parse_margins("conformal-motion:0.2").label == "cpm0.2"
    assert parse_margins("conformal-shortfall:0.05").label == "cps0.05"
    with pytest.raises(PipelineError, match="need the closed-loop calibration"):
        parse_margins("conformal-shortfall:0.1:real")
    with pytest.raises(PipelineError, match="need the closed-loop calibration"):
        parse_margins("conformal-motion:0.1:real")
    assert MarginSpec("conformal").resolve_classes("constant_velocity", 4, None) is None


def test_per_class_margins_on_real_data_are_refused_for_the_true_reason():
    """The refusal said real scenes hold no human observed for fewer than L steps, so a motion class could
    not be calibrated on them; they hold every class (ETH/hotel val: new 164, standing 71, slow 43, walking
    276 rows). The real-data calibration computes no margins per class, which is what the message says."""
    for mode in ("conformal-motion", "conformal-shortfall"):
        with pytest.raises(PipelineError) as caught:
            parse_margins(f"{mode}:0.1:real")
        message = str(caught.value)
        assert "real-data calibration computes one margin per horizon step for all humans" in message
        assert "none per motion class" in message and "fewer than L steps" not in message
    assert "no robot to measure a distance shortfall" in str(caught.value)


def _store(tmp_path, classes: bool) -> None:
    """19 samples per class, class c's step-k error i/100 * (c + 1) * k: margins 0.18 (c + 1) k."""
    errors, motion = class_errors(4)
    save_calibration(constant_velocity_block(errors, classes=motion if classes else None), tmp_path)


def test_a_calibration_without_class_margins_is_refused(tmp_path, monkeypatch):
    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path))
    _store(tmp_path, classes=False)
    for mode in ("conformal-motion", "conformal-shortfall"):
        # The command it names runs as given (the source is required).
        command = (
            "crowdmpc calibrate --predictor constant_velocity --source closed-loop --alpha 0.1 --episodes 200"
        )
        with pytest.raises(PipelineError, match=f"no {mode} margins per motion class.*recalibrate") as caught:
            parse_margins(mode).resolve_classes("constant_velocity", 4, None)
        assert str(caught.value).endswith(command)


def test_a_block_without_class_margins_made_beyond_the_sensor_range_bound_quotes_a_command_calibrate_runs(
    tmp_path, monkeypatch
):
    """Stored behind a 2000 m sensor before crowdsim.world.SENSOR_RANGE's 1000 m, the block's refusal quoted
    `--sensor-range 2000 --episodes 200`, which calibrate refuses now: it quotes the run's view's command."""
    # no shipped block: one seeing everyone would be taken before it
    monkeypatch.setenv("CROWDMPC_CHECKPOINTS", str(tmp_path))
    errors, _ = class_errors(4)
    save_calibration(constant_velocity_block(errors, details={"sensor_range": 2000.0}), tmp_path)
    with pytest.raises(PipelineError) as caught:
        parse_margins("conformal-motion").resolve_classes("constant_velocity", 4, None)
    assert str(caught.value).endswith(
        "recalibrate with enough episodes: crowdmpc calibrate --predictor constant_velocity --source "
        "closed-loop --alpha 0.1 --episodes 200; the block was made behind a 2000 m sensor before calibrate "
        "bounded the range (the sensor range must be at most 1000 m, got 2000.0) and cannot be made again: "
        "the command makes one of the view asked for, planned with before it"
    )


def _margins(controller, obs) -> np.ndarray:
    return controller._crowd_allowances(obs, np.zeros((1, 4)), np.zeros(1, bool))["human_margins"]


def test_the_controller_gives_each_human_its_class_margin(tmp_path, monkeypatch):
    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path))
    _store(tmp_path, classes=True)
    spec = ControllerSpec("cmpc", "constant_velocity", margins=parse_margins("conformal-motion"))
    controller = make_controller(spec)
    assert controller.cfg.human_margins == ()  # nothing for everyone: every human its own
    described = controller.describe()["config"]["margins"]
    assert described["label"] == "cpm0.1" and described["classes"]["quantiles"][3][0] == pytest.approx(0.72)
    # Window of L = 8 positions, 0.4 s apart (2.8 s): human 0 stands, human 1 walks 1 m/s.
    history = np.zeros((8, 1 + 2, 2))
    history[:, 2, 0] = np.arange(8) * 0.4
    obs = SimpleNamespace(history=history, human_observed=None, n_robots=1, step=10, dt=0.4)
    margins = _margins(controller, obs)
    np.testing.assert_allclose(margins[:, 0], 0.18 * 2 * np.arange(1, 5))  # standing: class 1
    np.testing.assert_allclose(margins[:, 1], 0.18 * 4 * np.arange(1, 5))  # walking: class 3
    early = _margins(
        controller, SimpleNamespace(history=history, human_observed=None, n_robots=1, step=3, dt=0.4)
    )
    np.testing.assert_allclose(early, np.outer(0.18 * np.arange(1, 5), [1, 1]))  # both still "new"


@pytest.mark.slow
def test_an_episode_with_class_margins_runs_and_keeps_its_distance(tmp_path, monkeypatch):
    from pipelines.loop.episode import run_episode

    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path))
    _store(tmp_path, classes=True)
    results = {}
    for text in ("none", "conformal-motion"):
        controller = make_controller(ControllerSpec("cmpc", "constant_velocity", margins=parse_margins(text)))
        results[text] = run_episode(controller, seed=3, scenario="circle", n_humans=5)
    assert results["conformal-motion"].metrics.min_distance > results["none"].metrics.min_distance


def act_once_standing(controller, layout):
    """``(observation, output)`` of ``controller``'s first step at which the humans of ``layout`` who never
    move count as standing: the 9th (motion classes need a full window of 8 observations)."""
    from crowdsim.env import CrowdEnv

    env = CrowdEnv()
    obs = env.reset_layout(layout)
    controller.reset(obs)
    for _ in range(8):
        out = controller.act(obs)
        obs, _, _ = env.step(out.accelerations)
    return obs, controller.act(obs)


def test_a_step_records_its_margins_and_guided_robots(tmp_path, monkeypatch):
    """Robot 0 of a row behind a line of standing humans is guided; every human's margins are in extra."""
    from crowdsim.scenarios import Layout

    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path))
    _store(tmp_path, classes=True)
    wall = np.stack([np.arange(-3.0, 1.5, 0.9), np.zeros(5)], axis=1)  # humans standing on their goals
    layout = Layout(
        robot_starts=np.array([[0.0, -3.0], [1.0, -5.0]]),
        robot_goals=np.array([[0.0, 3.0], [5.0, -5.0]]),
        human_starts=wall,
        human_goals=wall,
    )
    spec = ControllerSpec(
        "cmpc",
        "constant_velocity",
        margins=parse_margins("conformal-motion"),
        mpc_overrides=(("guidance", "standing"),),
    )
    _, out = act_once_standing(make_controller(spec), layout)
    assert np.asarray(out.extra["human_margins"]).shape == (4, 5)
    assert np.allclose(np.asarray(out.extra["human_margins"])[:, 0], 0.18 * 2 * np.arange(1, 5))
    assert list(out.extra["guided"]) == [0]  # robot 1's way east is free
    assert out.extra["guided"][0][0] > 1.0  # round the row's right end


def test_calibrate_names_a_block_stored_without_class_margins_and_an_empty_held_out_class(capsys):
    from pipelines.experiments.calibration_report import class_coverage_report, missing_class_margins

    errors, motion = class_errors(4)
    full = constant_velocity_block(errors, classes=motion, shortfall=errors)
    assert missing_class_margins([full]) == []
    # A class needs 9 samples at alpha 0.1 (ceil(1/0.1 - 1)); here the first has none.
    few = constant_velocity_block(errors[motion != 0], classes=motion[motion != 0])
    (line,) = missing_class_margins([few])
    assert "conformal-motion and conformal-shortfall will refuse this calibration" in line
    assert "fewer than 9 samples at some step (more --episodes give them)" in line
    # Held-out samples of the first class only (its own 19: 18 within 0.18 k), none for the others.
    class_coverage_report([full], errors[motion == 0], motion[motion == 0])
    rows = capsys.readouterr().out.splitlines()[1:]
    assert rows[0].endswith("held-out coverage: 94.7%, 94.7%, 94.7%, 94.7%")
    assert all(row.endswith("held-out coverage: no held-out samples in this class") for row in rows[1:])


def test_calibrate_does_not_store_a_block_without_class_margins_over_one_with_them(tmp_path, monkeypatch):
    """A short trial calibration replaced the block in force (shipped or the user's) by one without margins
    per motion class, and conformal-shortfall, which safe_crossing.toml plans with, then refused the
    predictor. Such a block is no longer stored over one that has them; a block that has them, or one that
    replaces a block without them, is."""
    from pipelines.commands.calibrate_store import _check_keeps_class_margins

    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path))
    errors, motion = class_errors(4)
    args = SimpleNamespace(predictor="constant_velocity", source="closed-loop")
    few = constant_velocity_block(errors[motion != 0], classes=motion[motion != 0])
    full = constant_velocity_block(errors, classes=motion, shortfall=errors)
    assert few.classes is None and few.shortfall is None
    with pytest.raises(PipelineError, match=r"alpha 0.1 has no .*\(in .*checkpoints/calibrations.json\)"):
        _check_keeps_class_margins([few], args)  # the shipped block has them
    save_calibration(full, tmp_path)
    with pytest.raises(PipelineError, match=f"not stored: .* alpha 0.1 .*\\(in {tmp_path}"):
        _check_keeps_class_margins([few], args)
    _check_keeps_class_margins([full], args)
    save_calibration(few, tmp_path)  # by hand: the block in force now has none to lose
    _check_keeps_class_margins([few], args)


def test_held_out_class_coverage_stays_with_its_block(capsys):
    """calibrate --json's holdout_class_coverage and holdout_shortfall_coverage skipped blocks without
    class margins, so entry i was no longer blocks[i]'s: a block without them has None in its place."""
    from pipelines.experiments.calibration_report import class_coverage_report

    errors, motion = class_errors(4)
    full = constant_velocity_block(errors, classes=motion, shortfall=errors)
    few = constant_velocity_block(errors[motion != 0], classes=motion[motion != 0])
    assert few.classes is None
    for shortfall in (False, True):
        report = class_coverage_report([few, full], errors, motion, shortfall=shortfall)
        assert report is not None and len(report) == 2 and report[0] is None
        assert report[1] is not None and report[1][0] == pytest.approx([18 / 19] * 4)
    assert class_coverage_report([few, full], None, None) is None


def test_labels_and_messages_name_an_alpha_of_many_digits_exactly(tmp_path, monkeypatch):
    """Labels and advice printed alpha with :g: 0.1234567 and 0.1234568 shared the label cpm0.123457 and
    the advice's --alpha 0.123457 made a block that never matches."""
    monkeypatch.setenv("CROWDMPC_CHECKPOINTS", str(tmp_path))
    assert MarginSpec("conformal-motion", alpha=0.1234567).label == "cpm0.1234567"
    assert MarginSpec("conformal", alpha=0.1234568).label == "cp0.1234568"
    errors, motion = class_errors(4)
    block = constant_velocity_block(errors[motion != 0], classes=motion[motion != 0])
    save_calibration(dataclasses.replace(block, alpha=0.1234567), tmp_path)
    with pytest.raises(
        PipelineError, match=r"alpha=0\.1234567 has no conformal-motion .*--alpha 0\.1234567 "
    ):
        MarginSpec("conformal-motion", alpha=0.1234567).resolve_classes("constant_velocity", 4, None)


def test_a_longer_history_keeps_the_calibrated_class_window(tmp_path, monkeypatch):
    """Closed-loop calibration classifies from 9 positions (the default world's history). With [world]
    obs_len = 12 the classes were read from all 12 rows: a human seen 10 times was still "new", and one who
    has stood for the last 9 positions but walked before them was "slow"; each got that class's margin."""
    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path))
    _store(tmp_path, classes=True)
    controller = make_controller(
        ControllerSpec("cmpc", "constant_velocity", margins=parse_margins("conformal-motion"))
    )
    history = np.zeros((12, 1 + 2, 2))
    history[:3, 1, 0] = [-1.2, -0.8, -0.4]  # walked 1 m/s, then stood still for the last 9 positions
    history[:, 2, 0] = np.arange(12) * 0.4  # walks 1 m/s throughout
    margins = _margins(
        controller, SimpleNamespace(history=history, human_observed=None, n_robots=1, step=9, dt=0.4)
    )
    np.testing.assert_allclose(margins[:, 0], 0.18 * 2 * np.arange(1, 5))  # standing: class 1
    np.testing.assert_allclose(margins[:, 1], 0.18 * 4 * np.arange(1, 5))  # walking: class 3


def test_a_history_shorter_than_the_class_window_is_refused(tmp_path, monkeypatch):
    """With [world] obs_len = 2 the classes were read from one step's motion, not 9 positions."""
    from crowdsim.env_config import EnvConfig

    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path))
    errors, motion = class_errors(4)
    save_calibration(constant_velocity_block(errors, classes=motion, shortfall=errors), tmp_path)
    short = dataclasses.replace(EnvConfig(), history_len=2)
    for mode in ("conformal-motion", "conformal-shortfall"):
        spec = ControllerSpec("cmpc", "constant_velocity", margins=parse_margins(mode))
        with pytest.raises(PipelineError, match=r"last 9 positions.*keeps 2.*--set world.obs_len=9"):
            make_controller(spec, short)
    make_controller(ControllerSpec("cmpc", "constant_velocity", margins=parse_margins("conformal")), short)


def _late_human(step, observed=None):
    """3 robots and one human walking at 1.25 m/s who entered the sensor range one step ago, its past padded
    with its first position as the simulator pads (a tracker's observation)."""
    from crowdsim.env import Observation

    robots = np.array([[-4.0, 0.0], [-4.0, 1.0], [-4.0, -1.0]])
    history = np.zeros((9, 4, 2))
    history[:, :3] = robots
    history[:, 3] = [0.0, 2.5]
    history[-1, 3] = [0.0, 2.0]
    return Observation(
        time=step * 0.4, step=step, robot_positions=robots, robot_velocities=np.zeros((3, 2)),
        robot_goals=-robots, robot_last_actions=np.zeros((3, 2)), robot_reached=np.zeros(3, bool),
        human_positions=history[-1, 3:], human_velocities=np.array([[0.0, -1.25]]),
        human_goals=history[-1, 3:], history=history, radius=0.3, dt=0.4, human_observed=observed,
    )  # fmt: skip


def test_a_human_tracked_for_two_steps_is_new_whatever_the_episode_step():
    """Counted as seen since step 0 (``obs.step + 1``), a human who entered late had a padded past that read
    as "slow" (or "standing" when seen once): a small margin instead of the "new" class's large one."""
    from pipelines.loop.motion_classes import observed_classes
    from predictors.conformal_classes import MOTION_CLASSES

    assert MOTION_CLASSES[observed_classes(_late_human(1))[0]] == "new"
    assert MOTION_CLASSES[observed_classes(_late_human(50, np.array([2])))[0]] == "new"
    assert MOTION_CLASSES[observed_classes(_late_human(50))[0]] == "slow"  # None: the simulator's count
    refused = r"obs\.human_observed must be 1 ints.*got float64 of shape \(1,\)"
    with pytest.raises(PipelineError, match=refused):
        observed_classes(_late_human(50, np.array([2.0])))
