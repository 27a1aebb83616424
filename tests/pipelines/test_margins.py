"""Safety margins: parsing, resolution from a calibration, the MPC planning with them, closed-loop errors."""

import dataclasses
import json
import math
import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from crowdsim.env import CrowdEnv
from pipelines.errors import PipelineError
from pipelines.experiments.calibrate import ClosedLoopPlan, PredictionErrors, closed_loop_errors
from pipelines.loop.controllers import ControllerSpec, ControlOutput, make_controller
from pipelines.loop.episode import run_episode
from pipelines.loop.margins import MarginSpec, parse_margins
from predictors.calibration_store import save_calibration
from predictors.errors import PredictorError
from tests.calibration_blocks import constant_velocity_block

REPO = Path(__file__).resolve().parents[2]


def test_parse_margins():
    assert parse_margins("none") == MarginSpec()
    assert parse_margins("conformal") == MarginSpec("conformal", alpha=0.1, source="closed-loop")
    assert parse_margins("conformal:0.05:real") == MarginSpec("conformal", alpha=0.05, source="real")
    assert parse_margins("fixed:0.1,0.2,0.3,0.4").values == (0.1, 0.2, 0.3, 0.4)
    assert parse_margins("conformal:0.05").label == "cp0.05"
    assert parse_margins("conformal:0.05:real").label == "cp0.05-real"
    assert parse_margins("fixed:0.1,0.2,0.3,0.4").label == "fixed0.1_0.2_0.3_0.4"
    for bad, match in (
        ("wide", "bad margins 'wide'"),
        ("conformal:x", "'x' is not a number"),
        ("conformal:1.5", r"alpha must be a number in \(0, 1\)"),
        ("conformal:0.1:guess", "unknown calibration source 'guess'"),
        ("fixed:0.1,-1,0,0", r"fixed margins must be numbers in \[0, 5.0\]"),
        ("fixed:nan", "not a finite number"),
        ("none:0.1", "bad margins"),
    ):
        with pytest.raises(PipelineError, match=match):
            parse_margins(bad)


@pytest.mark.parametrize(
    "bad", ["conformal:", "conformal: ", "conformal::real", "conformal:0.1:", "conformal-shortfall:", "none:"]
)
def test_an_empty_field_after_a_colon_is_refused(bad):
    """`--margins conformal:$ALPHA` with ALPHA unset planned at the default alpha 0.1, and `conformal:0.1:`
    with the default source, as if the colon and what should follow it were not there."""
    with pytest.raises(PipelineError, match=r"bad margins|calibration source ''"):
        parse_margins(bad)


def test_resolution_reads_the_calibration_and_checks_the_horizon(tmp_path, monkeypatch):
    monkeypatch.setenv("CROWDMPC_CHECKPOINTS", str(tmp_path))
    assert MarginSpec().resolve("constant_velocity", 4, None) == ()
    assert MarginSpec("fixed", values=(0.1, 0.2)).resolve(None, 2, None) == (0.1, 0.2)
    with pytest.raises(PipelineError, match="one value per horizon step"):
        MarginSpec("fixed", values=(0.1, 0.2)).resolve(None, 4, None)
    with pytest.raises(PredictorError, match="run: crowdmpc calibrate --predictor constant_velocity"):
        MarginSpec("conformal").resolve("constant_velocity", 4, None)
    # Scores 0.01 .. 0.20 per step k (times k): the 0.9 quantile of 19 samples is the 18th smallest.
    errors = np.outer(np.arange(1, 20) / 100.0, [1.0, 2.0, 3.0, 4.0])
    save_calibration(constant_velocity_block(errors))
    assert MarginSpec("conformal").resolve("constant_velocity", 4, None) == pytest.approx(
        (0.18, 0.36, 0.54, 0.72)
    )
    assert MarginSpec("conformal").resolve("constant_velocity", 2, None) == pytest.approx((0.18, 0.36))
    with pytest.raises(PipelineError, match="covers 4 steps, the MPC's horizon is 6"):
        MarginSpec("conformal").resolve("constant_velocity", 6, None)
    with pytest.raises(PredictorError, match="weights changed since calibration"):
        MarginSpec("conformal").resolve("constant_velocity", 4, "f" * 64)


def test_the_controller_plans_with_the_margins_and_says_so():
    spec = ControllerSpec("cmpc", "constant_velocity", margins=parse_margins("fixed:0.1,0.2,0.3,0.4"))
    controller = make_controller(spec)
    assert controller.cfg.human_margins == (0.1, 0.2, 0.3, 0.4)
    described = controller.describe()["config"]["margins"]
    assert described == {"mode": "fixed", "label": "fixed0.1_0.2_0.3_0.4", "margins_m": [0.1, 0.2, 0.3, 0.4]}
    paper = make_controller(ControllerSpec("cmpc", "constant_velocity"))
    assert paper.cfg.human_margins == () and paper.describe()["config"]["margins"]["mode"] == "none"
    with pytest.raises(PipelineError, match="through ControllerSpec.margins"):
        ControllerSpec("cmpc", mpc_overrides=(("human_margins", (0.1,) * 4),))


def test_margins_keep_the_robots_further_from_a_head_on_human():
    """One robot, one human walking straight at it: a 0.4 m margin on every step keeps them further apart."""
    from crowdsim.scenarios import Layout

    layout = Layout(
        robot_starts=np.array([[0.0, -3.0]]),
        robot_goals=np.array([[0.0, 3.0]]),
        human_starts=np.array([[0.05, 3.0]]),
        human_goals=np.array([[0.05, -3.0]]),
    )
    distances = {}
    for text in ("none", "fixed:0.4,0.4,0.4,0.4"):
        controller = make_controller(ControllerSpec("cmpc", "constant_velocity", margins=parse_margins(text)))
        env = CrowdEnv()
        obs = env.reset_layout(layout)
        controller.reset(obs)
        done = False
        while not done:
            obs, done, _ = env.step(controller.act(obs).accelerations)
        traj = env.trajectory()
        distances[text] = float(
            np.linalg.norm(traj.robot_positions[:, 0] - traj.human_positions[:, 0], axis=-1).min()
        )
    assert distances["fixed:0.4,0.4,0.4,0.4"] > distances["none"] + 0.1


def test_prediction_errors_by_hand():
    """A prediction made at step 1 of a 3-step episode: k = 1, 2 are scored, k = 3 is past the end (NaN)."""
    observer = PredictionErrors(near=2.0)
    obs = SimpleNamespace(
        step=1,
        n_humans=2,
        n_robots=1,
        human_positions=np.array([[1.0, 0.0], [5.0, 0.0]]),  # the second human is 5 m from the robot
        robot_positions=np.array([[0.0, 0.0]]),
        history=np.zeros((8, 3, 2)),  # 2 positions observed of a window of 8: the "new" class
        human_observed=None,  # the simulator's: step + 1
        dt=0.4,
    )
    prediction = np.array([[[1.0, 0.1], [5.0, 0.0]], [[1.0, 0.5], [5.0, 0.0]], [[1.0, 0.9], [5.0, 0.0]]])
    observer.on_reset(obs, {})
    observer.on_step(obs, ControlOutput(accelerations=np.zeros((1, 2)), prediction=prediction), obs)
    observer.on_step(obs, ControlOutput(accelerations=np.zeros((1, 2))), obs)  # no prediction: skipped
    truth = np.array([[[0, 0], [5, 0]], [[1, 0], [5, 0]], [[1, 0.2], [5, 0]], [[1, 0.2], [5, 0]]], float)
    robots = np.array([[[0, 0]], [[0, 0]], [[1, 1]], [[1, 1]]], float)  # at (1, 1) from step 2 on
    observer.on_end(SimpleNamespace(human_positions=truth, robot_positions=robots, human_present=None))
    errors = observer.errors
    assert errors.shape == (1, 3)  # only the human within 2 m
    np.testing.assert_allclose(errors[0, :2], [0.1, 0.3])
    assert math.isnan(errors[0, 2])
    assert observer.classes.tolist() == [0]
    # Distance shortfall at the robot's realised position: k = 1 (step 2), robot (1, 1), predicted (1, 0.1)
    # 0.9 away, realised (1, 0.2) 0.8 away: 0.1. k = 2 (step 3): predicted (1, 0.5) 0.5 away, realised 0.8
    # away: the human stayed further than predicted, -0.3, clipped to 0.
    np.testing.assert_allclose(observer.shortfall[0, :2], [0.1, 0.0], atol=1e-12)
    assert math.isnan(observer.shortfall[0, 2])


def test_prediction_errors_score_the_people_predicted_while_they_are_tracked():
    """A replayed crowd's step: person 2 is not tracked (not predicted: NaN, and a track length of 0, which
    classing every human refused), person 1 has just appeared (class new) and leaves after one step (no truth
    at k = 2), person 0 has stood for 9 rows (class standing). All three are within ``near``."""
    from crowdsim.env import Observation

    obs = Observation(
        time=0.4, step=1, robot_positions=np.zeros((1, 2)), robot_velocities=np.zeros((1, 2)),
        robot_goals=np.ones((1, 2)), robot_last_actions=np.zeros((1, 2)), robot_reached=np.array([False]),
        human_positions=np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0]]), human_velocities=np.zeros((3, 2)),
        human_goals=np.zeros((3, 2)), history=np.zeros((8, 4, 2)), radius=0.3, dt=0.4,
        human_observed=np.array([9, 1, 0]), human_present=np.array([True, True, False]),
    )  # fmt: skip
    prediction = np.array([[[1.0, 0.1], [0.0, 1.5], [np.nan] * 2], [[1.0, 0.2], [0.0, 2.0], [np.nan] * 2]])
    observer = PredictionErrors(near=2.0)
    observer.on_reset(obs, {})
    observer.on_step(obs, ControlOutput(accelerations=np.zeros((1, 2)), prediction=prediction), obs)
    truth = np.zeros((4, 3, 2))
    truth[:, 0], truth[:, 1], truth[:, 2] = [1.0, 0.0], [0.0, 1.2], [-1.0, 0.0]
    present = np.array([[True, False, False], [True, True, False], [True, True, True], [True, False, True]])
    observer.on_end(
        SimpleNamespace(human_positions=truth, robot_positions=np.zeros((4, 1, 2)), human_present=present)
    )
    np.testing.assert_allclose(observer.errors, [[0.1, 0.2], [0.3, math.nan]])  # person 2 never scored
    assert observer.classes.tolist() == [1, 0]


@pytest.mark.slow
def test_closed_loop_errors_of_constant_velocity():
    plan = ClosedLoopPlan("constant_velocity", episodes=2, humans=(3,))
    errors, classes, shortfall, details, sha256 = closed_loop_errors(plan, progress=False)
    assert shortfall.shape == errors.shape
    both = np.isfinite(shortfall) & np.isfinite(errors)
    assert np.all(shortfall[both] <= errors[both] + 1e-12)  # the triangle inequality
    assert classes.shape == (len(errors),) and set(classes.tolist()) <= {0, 1, 2, 3}
    assert errors.ndim == 2 and errors.shape[1] == 4 and len(errors) > 10
    assert details["seeds"] == [1_000_000, 1_000_001]
    assert sha256 is None  # constant velocity plans with no weights
    finite = errors[np.isfinite(errors)]
    assert (finite >= 0).all() and np.nanmedian(errors[:, 3]) >= np.nanmedian(errors[:, 0])
    # The calibration episodes are ordinary closed-loop episodes of their seeds.
    again = run_episode(
        make_controller(ControllerSpec("cmpc", "constant_velocity")),
        seed=1_000_000,
        scenario="circle",
        n_humans=3,
    )
    assert again.metrics.n_steps > 0
    with pytest.raises(PipelineError, match="calibration runs cmpc or dmpc"):
        ClosedLoopPlan("constant_velocity", controller="orca")


@pytest.mark.slow
def test_calibrate_cli_stores_blocks_and_checks_them_on_held_out_episodes(tmp_path, monkeypatch, capsys):
    import json

    from pipelines.cli import main
    from predictors.calibration_store import read_calibrations

    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path))  # calibrate writes to the user zoo
    # Alphas the shipped zoo has no block for: two episodes may leave a motion class short of samples, and a
    # block without per-class margins is not stored over a shipped one that has them.
    args = ["calibrate", "--predictor", "constant_velocity", "--source", "closed-loop", "--alpha", "0.45,0.3"]
    args += ["--episodes", "2", "--humans", "3", "--no-progress", "--json", str(tmp_path / "c.json")]
    assert main([*args, "--holdout", "--holdout-margins", "conformal:0.45"]) == 0
    out = capsys.readouterr().out
    assert "planning with margins conformal:0.45" in out and "held-out coverage (target 55%)" in out
    blocks = read_calibrations(tmp_path)
    assert [(b.predictor, b.source, b.alpha) for b in blocks] == [
        ("constant_velocity", "closed-loop", 0.3),
        ("constant_velocity", "closed-loop", 0.45),
    ]
    assert blocks[0].details["seeds"] == [1_000_000, 1_000_001] and blocks[0].details["margins"] == "none"
    payload = json.loads((tmp_path / "c.json").read_text())
    assert len(payload["holdout_coverage"]) == 2 and all(0 <= c <= 1 for c in payload["holdout_coverage"][0])
    assert main([*args[:-2], "--holdout-margins", "wide"]) == 2
    assert "bad margins 'wide'" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        (lambda: MarginSpec("conformal", alpha=0.0), r"alpha must be a number in \(0, 1\), got 0.0"),
        (lambda: MarginSpec("conformal", alpha=1.0), r"alpha must be a number in \(0, 1\), got 1.0"),
        (lambda: MarginSpec("conformal", alpha=True), r"alpha must be a number in \(0, 1\), got True"),
        (lambda: MarginSpec("fixed", values=(5.01,)), r"must be numbers in \[0, 5.0\] m, got \[5.01\]"),
        (lambda: MarginSpec("none", values=(0.1,)), "other modes take none"),
        (lambda: MarginSpec("conformal", values=(0.1,)), "other modes take none"),
        (lambda: MarginSpec("fixed"), r"fixed margins need values"),
    ],
    ids=[
        "alpha-0",
        "alpha-1",
        "alpha-bool",
        "over-5m",
        "none-with-values",
        "conformal-with-values",
        "fixed-empty",
    ],
)
def test_margin_specs_outside_their_ranges_are_refused(spec, message):
    """alpha = 0 would ask for the largest error ever seen (infinite with finite data), alpha = 1 for no
    margin at all; values given to a mode that ignores them would be silently dropped."""
    with pytest.raises(PipelineError, match=message):
        spec()


def test_margins_at_the_ends_of_their_range_are_kept():
    # 0 m (no allowance at a step) and 5 m (MAX_MARGIN) are both allowed: the range is closed
    spec = MarginSpec("fixed", values=(0, 5.0, 0.05, 0.125))
    assert spec.values == (0.0, 5.0, 0.05, 0.125)
    # the label names each value exactly, so 0.05 and 0.125 never share a cell key with 0.1 or 0.12
    assert spec.label == "fixed0_5_0.05_0.125"
    assert MarginSpec("fixed", values=(0.01,) * 2).label != MarginSpec("fixed", values=(0.0,) * 2).label


def test_fixed_margin_labels_are_exact_beyond_six_digits_and_unchanged_within():
    """Two margins that differ in the 7th digit are two cells; the labels :g already wrote exactly (the
    cell keys of existing sweep directories) stay as they were."""
    a, b = (parse_margins(f"fixed:{m},0.2,0.3,0.4") for m in ("0.1234561", "0.1234564"))
    assert (a.label, b.label) == ("fixed0.1234561_0.2_0.3_0.4", "fixed0.1234564_0.2_0.3_0.4")
    assert a.describe(a.values)["label"] == a.label
    assert parse_margins("fixed:0.1,0.2,0.3,0.4").label == "fixed0.1_0.2_0.3_0.4"
    assert MarginSpec("fixed", values=(0.0, 1.0, 2.5e-05, 1e-06)).label == "fixed0_1_2.5e-05_1e-06"
    assert MarginSpec("fixed", values=(1 / 3,)).label == f"fixed{1 / 3!r}"


def test_fixed_margins_longer_than_the_horizon_are_refused():
    """Five values for a horizon of 4 means the user had another horizon in mind: not cut silently."""
    with pytest.raises(PipelineError, match=r"one value per horizon step \(4\), got 5"):
        MarginSpec("fixed", values=(0.1,) * 5).resolve(None, 4, None)


def test_a_calibration_one_step_short_of_the_horizon_is_refused(tmp_path, monkeypatch):
    monkeypatch.setenv("CROWDMPC_CHECKPOINTS", str(tmp_path))
    save_calibration(constant_velocity_block(np.outer(np.arange(1, 20) / 100.0, [1.0, 2.0, 3.0, 4.0])))
    assert len(MarginSpec("conformal").resolve("constant_velocity", 4, None)) == 4
    with pytest.raises(PipelineError, match="covers 4 steps, the MPC's horizon is 5"):
        MarginSpec("conformal").resolve("constant_velocity", 5, None)


def test_shortfall_margins_come_from_the_shortfall_table(tmp_path, monkeypatch):
    """conformal-shortfall plans with the distance-shortfall quantiles, conformal-motion with the
    displacement ones: with shortfalls 1.5 times the errors, class c's step-k margin is 0.27 (c + 1) k, not
    0.18 (c + 1) k (tests/calibration_blocks.class_errors: the 18th smallest of 19 samples)."""
    from tests.calibration_blocks import class_errors

    monkeypatch.setenv("CROWDMPC_CHECKPOINTS", str(tmp_path))
    errors, motion = class_errors(4)
    save_calibration(constant_velocity_block(errors, classes=motion, shortfall=1.5 * errors))
    moving = MarginSpec("conformal-motion").resolve_classes("constant_velocity", 4, None)
    short = MarginSpec("conformal-shortfall").resolve_classes("constant_velocity", 4, None)
    assert moving.quantiles[0][3] == pytest.approx(0.18 * 4)
    assert short.quantiles[0][3] == pytest.approx(0.27 * 4)
    # past the 5 m a fixed margin may have (0.36 * 4 * 4 = 5.76 m for class 3 at step 4): refused, naming it
    save_calibration(constant_velocity_block(errors, classes=motion, shortfall=2 * errors))
    with pytest.raises(PipelineError, match="has a margin of 5.76 m, past the 5 m any plan"):
        MarginSpec("conformal-shortfall").resolve_classes("constant_velocity", 4, None)
    assert MarginSpec("conformal-motion").resolve_classes("constant_velocity", 4, None) == moving


def test_describe_states_alpha_and_source_of_calibrated_margins():
    described = MarginSpec("conformal", alpha=0.05, source="real").describe((0.1, 0.2))
    assert described == {
        "mode": "conformal",
        "label": "cp0.05-real",
        "margins_m": [0.1, 0.2],
        "alpha": 0.05,
        "source": "real",
    }
    assert MarginSpec().describe(()) == {"mode": "none", "label": "none", "margins_m": []}


def test_a_record_names_the_calibration_its_margins_came_from():
    """One block is kept per predictor and alpha, and a recalibration replaces it: a record said which alpha
    and source, not which block (when it was made, from what data, under which conventions)."""
    from predictors.calibration_store import find_calibration

    block = find_calibration("social_lstm_eth", "closed-loop", 0.1)
    spec = ControllerSpec("cmpc", "social_lstm_eth", margins=parse_margins("conformal"))
    controller = make_controller(spec)
    assert controller.describe()["config"]["margins"]["calibration"] == {
        "created": block.created,
        "data_sha256": block.data_sha256,
        "zoo": "shipped",
        "profile": "paper",
        "visibility": "visible",
        "controller": "cmpc",
        "humans": [5, 6, 7, 8, 9],
    }
    real = MarginSpec("conformal", alpha=0.1, source="real").calibration("constant_velocity", None)
    assert real is not None and set(real) == {"created", "data_sha256", "zoo"}  # real scenes: no conventions
    assert MarginSpec().calibration("social_lstm_eth", None) is None
    fixed = make_controller(ControllerSpec("cmpc", margins=parse_margins("fixed:0.1,0.1,0.1,0.1")))
    assert "calibration" not in fixed.describe()["config"]["margins"]


def test_calibrated_margins_need_a_predictor_and_specs_may_be_padded():
    """ORCA with conformal margins has no predictor whose calibration to read: one line saying so. A spec
    read from a config file may carry spaces around it."""
    with pytest.raises(PipelineError, match="conformal margins need a predictor; this controller uses none"):
        MarginSpec("conformal").resolve(None, 4, None)
    assert parse_margins(" conformal:0.05 ") == MarginSpec("conformal", alpha=0.05)


def test_real_margins_of_the_oracle_name_what_runs(tmp_path, monkeypatch, capsys):
    """No real calibration of the ORCA oracle can exist (`calibrate --source real` refuses it); the refusal
    said to run exactly that command. It now names the oracle's closed-loop margins."""
    from pipelines.cli import main

    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path))
    with pytest.raises(PipelineError) as caught:
        parse_margins("conformal:0.05:real").resolve("orca_oracle", 4, None)
    message = str(caught.value)
    # "margins", not "--margins": calibrate's --holdout-margins reaches this refusal too
    assert "no real calibration" in message and "(margins conformal:0.05)" in message
    assert "--source real" not in message
    argv = ["calibrate", "--predictor", "orca_oracle", "--source", "real", "--alpha", "0.05"]
    assert main(argv) == 2  # what the refusal used to name
    assert "use --source closed-loop" in capsys.readouterr().err


def test_a_short_oracle_calibration_offers_no_real_one(tmp_path, monkeypatch, capsys):
    """At a horizon past the oracle's closed-loop calibration, simulate and calibrate said to calibrate real
    scenes instead, which `calibrate --source real` refuses for the oracle."""
    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path))
    with pytest.raises(PipelineError) as caught:
        parse_margins("conformal:0.1").resolve("orca_oracle", 6, None)
    message = str(caught.value)
    assert "plan with a horizon of at most 4 (mpc.horizon)" in message
    assert "real" not in message.replace("closed-loop calibration only", "")
    _episodes(monkeypatch)
    argv = [
        "calibrate",
        "--predictor",
        "orca_oracle",
        "--source",
        "closed-loop",
        "--horizon",
        "6",
        "--dry-run",
    ]
    assert _refused(capsys, argv).endswith("(its horizon, which calibrate does not change); use --horizon 4")


# ------------------------------------------------------------------------- calibrate: refused before the work
CALIBRATE = ["calibrate", "--predictor", "constant_velocity", "--source", "closed-loop", "--no-progress"]


def _episodes(monkeypatch, errors: np.ndarray | None = None) -> list:
    """calibrate's closed-loop episodes replaced by synthetic errors (tests/calibration_blocks.class_errors:
    19 per motion class, shortfall = error) or ``errors``; returns the plans they were asked for."""
    from pipelines.experiments import calibrate as experiment
    from tests.calibration_blocks import synthetic_closed_loop

    plans = []

    def measured(plan, progress=True, check_weights=None):
        plans.append(plan)
        return synthetic_closed_loop(plan, errors)

    monkeypatch.setattr(experiment, "closed_loop_errors", measured)
    return plans


def _refused(capsys, argv: list[str]) -> str:
    from pipelines.cli import main

    try:
        code = main(argv)
    except SystemExit as exc:  # the parser's own errors (--alpha)
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err
    return err


def test_calibrate_refuses_an_alpha_no_calibration_can_reach(monkeypatch, capsys):
    """--alpha 1e-309 ran the episodes, then min_samples overflowed into a traceback; margins that small
    passed parse_margins. Both are refused in one line, before any episode."""
    plans = _episodes(monkeypatch)
    err = _refused(capsys, [*CALIBRATE, "--alpha", "0.1,1e-309", "--dry-run"])
    assert "--alpha needs numbers of at least 1e-12, got '0.1,1e-309'" in err and plans == []
    with pytest.raises(PipelineError, match="margin alpha must be at least 1e-12, got 1e-13"):
        parse_margins("conformal:1e-13")


def test_calibrate_refuses_a_repeated_alpha(monkeypatch, capsys):
    """--alpha 0.5,0.5 said "wrote 2 block(s)" and stored one."""
    plans = _episodes(monkeypatch)
    assert "--alpha names 0.5 twice in '0.5,0.5'" in _refused(capsys, [*CALIBRATE, "--alpha", "0.5,0.5"])
    err = _refused(capsys, [*CALIBRATE, "--alpha", "0.1,0.2,0.1000000000000001"])
    assert "names 0.1 and 0.1000000000000001, one calibration," in err and plans == []


def test_calibrate_refuses_a_crowd_too_large_before_any_episode(monkeypatch, capsys):
    """--humans 5,51 ran the 5-human episodes, then the first 51-human one failed, in a message that did not
    name --humans ("n_humans must be in [0, 50], got 51")."""
    plans = _episodes(monkeypatch)
    err = _refused(capsys, [*CALIBRATE, "--humans", "5,51", "--episodes", "3", "--dry-run"])
    assert err == "crowdmpc calibrate: error: --humans must be in 1..50, got 51" and plans == []


def test_calibrate_near_inf_is_stored_as_null(monkeypatch):
    """near = inf (the module's "scores everyone") ran every episode, then failed to store the block:
    JSON has no infinity. It is stored as null."""
    from predictors.calibration import Calibration

    monkeypatch.setattr(
        "pipelines.loop.episode.run_episode",
        lambda *a, **k: SimpleNamespace(metrics=SimpleNamespace(success=1)),
    )
    details = closed_loop_errors(
        ClosedLoopPlan("constant_velocity", episodes=1, near=math.inf), False
    ).details
    assert details["near"] is None
    block = constant_velocity_block(np.outer(np.arange(1, 20) / 100.0, [1.0, 2.0, 3.0, 4.0]))
    assert Calibration.from_json(block.to_json() | {"details": details}, "f").details["near"] is None
    with pytest.raises(PipelineError, match=r"--near must be > 0 m \(inf scores everyone\), got nan"):
        ClosedLoopPlan("constant_velocity", near=math.nan)


def test_calibrate_says_no_human_came_near(monkeypatch, capsys):
    """With no human within --near the message blamed the horizon: "the controller predicts (0,) steps"."""
    _episodes(monkeypatch, errors=np.zeros((0, 0)))
    err = _refused(capsys, [*CALIBRATE, "--near", "0.001", "--episodes", "3", "--dry-run"])
    assert err.endswith(
        "no human came within --near 0.001 m of a robot in 3 episode(s), so there is no error "
        "to calibrate; raise --near or --episodes"
    )


def test_closed_loop_calibration_refuses_another_horizon_before_the_episodes(monkeypatch, capsys):
    """The closed loop predicts the MPC's 4 steps: --horizon 6 ran every episode, then failed."""
    plans = _episodes(monkeypatch)
    err = _refused(capsys, [*CALIBRATE, "--horizon", "6", "--dry-run"])
    assert err.endswith("use --horizon 4, or calibrate real scenes at 6 steps: --source real --horizon 6")
    assert plans == []


def test_a_short_calibration_says_what_gives_the_horizon(tmp_path, monkeypatch):
    """ "recalibrate with that horizon" was impossible for the closed loop; the message names what works."""
    monkeypatch.setenv("CROWDMPC_CHECKPOINTS", str(tmp_path))
    errors = np.outer(np.arange(1, 20) / 100.0, [1.0, 2.0, 3.0, 4.0])
    save_calibration(constant_velocity_block(errors))
    with pytest.raises(PipelineError) as closed:
        MarginSpec("conformal").resolve("constant_velocity", 6, None)
    assert (
        "plan with a horizon of at most 4 (mpc.horizon), or calibrate real scenes at 6 steps: crowdmpc "
        "calibrate --predictor constant_velocity --source real --alpha 0.1 --horizon 6, and plan with "
        "--margins conformal:0.1:real" in str(closed.value)
    )
    save_calibration(dataclasses.replace(constant_velocity_block(errors), source="real"))
    with pytest.raises(
        PipelineError,
        match="recalibrate the real scenes at that horizon: crowdmpc calibrate "
        "--predictor constant_velocity --source real --alpha 0.1 --horizon 6$",
    ):
        MarginSpec("conformal", source="real").resolve("constant_velocity", 6, None)


def test_held_out_margins_are_resolved_before_the_episodes(tmp_path, monkeypatch, capsys):
    """--holdout-margins conformal:0.3 with --dry-run (nothing stored), or an alpha this run does not
    calibrate and no block has, failed after the calibration episodes. One this run stores is taken. With
    --dry-run, one of this run's alphas is refused whether a block of it is stored or not: the held-out
    episodes planned with the stored block, its coverage printed as the new block's."""
    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path))
    plans = _episodes(monkeypatch)
    held = [*CALIBRATE, "--holdout", "--holdout-margins", "conformal:0.3"]
    err = _refused(capsys, [*held, "--alpha", "0.5"])
    assert "--holdout-margins conformal:0.3: no closed-loop calibration at alpha=0.3" in err
    err = _refused(capsys, [*held, "--alpha", "0.3", "--dry-run"])
    assert "plans the held-out episodes with this run's block, which --dry-run does not store" in err
    assert (
        "drop --dry-run (with CROWDMPC_ZOO=DIR, a scratch copy of your user zoo, to keep yours as it is)"
        in err
    )
    assert plans == []
    from pipelines.cli import main

    assert main([*held, "--alpha", "0.3"]) == 0  # stored by this run, then planned with
    assert [plan.margins for plan in plans] == [MarginSpec(), MarginSpec("conformal", alpha=0.3)]


def test_a_calibrations_file_calibrate_cannot_extend_is_refused_before_the_episodes(
    tmp_path, monkeypatch, capsys
):
    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path))
    (tmp_path / "calibrations.json").write_text(
        '{"format": "crowdmpc-calibrations", "version": 2, "calibrations": []}'
    )
    plans = _episodes(monkeypatch)
    assert 'calibrations.json: unsupported "version" 2, expected 1' in _refused(capsys, [*CALIBRATE])
    assert plans == []
    from pipelines.cli import main

    assert main([*CALIBRATE, "--dry-run"]) == 0  # stores nothing, so reads no file


def test_real_calibration_refuses_held_out_margins(monkeypatch, capsys):
    """Held-out real scenes plan nothing: --holdout-margins was ignored, yet recorded in --json."""
    import pipelines.commands.calibrate as command

    monkeypatch.setattr(command, "_real", lambda *a: pytest.fail("read the scenes"))
    argv = ["calibrate", "--predictor", "constant_velocity", "--source", "real", "--holdout"]
    err = _refused(capsys, [*argv, "--holdout-margins", "conformal-motion:0.3", "--dry-run"])
    assert "--holdout-margins is for --source closed-loop" in err


def test_held_out_coverage_targets_are_printed_exactly():
    """The target was rounded to a whole percent: alpha 0.025 printed "target 98%", 0.005 "target 100%"."""
    from pipelines.experiments.calibration_report import format_coverage

    alphas = (0.1, 0.025, 0.005, 0.001, 1e-05)
    text = format_coverage(alphas, [[0.5]] * len(alphas), [[0.9]] * len(alphas))
    targets = [line.split("(target ")[1].split(")")[0] for line in text.splitlines()]
    assert targets == ["90%", "97.5%", "99.5%", "99.9%", "99.999%"]


def test_real_calibration_refuses_a_horizon_longer_than_the_scenes_before_reading_them(monkeypatch, capsys):
    """--horizon 13 for social_lstm_eth (9 observed steps) failed in the first scene file, as if the file were
    at fault ("scene 553 has 21 steps, the evaluation needs 22 ... a test/ file without ground truth?")."""
    import predictors.data.locate as locate

    monkeypatch.setattr(locate, "protocol_files", lambda *a, **k: pytest.fail("read the scenes"))
    argv = ["calibrate", "--predictor", "constant_velocity", "--source", "real", "--dry-run", "--no-progress"]
    err = _refused(capsys, [*argv, "--horizon", "20"])
    assert err.endswith(
        "--horizon 20: the real scenes have 21 steps and constant_velocity observes 2 of them, so --source "
        "real calibrates at most 19 steps for it"
    )


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (
            ["--source", "real", "--near", "-1", "--episodes", "3", "--controller", "dmpc"],
            "--episodes, --controller, --near are for --source closed-loop (its simulated episodes); "
            "--source real measures recorded scenes: leave them out",
        ),
        (
            ["--source", "real", "--seed", "1000000"],
            "--seed is for --source closed-loop",
        ),  # the default, typed
        (["--source", "closed-loop", "--data-dir", "/nonexistent"], "--data-dir is for --source real"),
        (
            ["--source", "closed-loop", "--holdout-margins", "fixed:1,1,1,1"],
            "--holdout-margins fixed:1,1,1,1: the held-out episodes of --holdout plan with these margins, "
            "and without --holdout none run: add --holdout or leave it out",
        ),
    ],
    ids=["real-closed-loop-options", "real-default-seed", "closed-loop-data-dir", "margins-without-holdout"],
)
def test_calibrate_refuses_options_that_would_change_nothing(argv, message, monkeypatch, capsys):
    """Closed-loop options (even invalid: --near -1) with --source real, --data-dir with closed-loop, and
    --holdout-margins without --holdout were accepted and ignored: the margins those of a plain run."""
    import pipelines.commands.calibrate as command

    plans = _episodes(monkeypatch)
    monkeypatch.setattr(command, "_real", lambda *a: pytest.fail("read the scenes"))
    base = ["calibrate", "--predictor", "constant_velocity", "--no-progress", "--dry-run"]
    assert message in _refused(capsys, [*base, *argv]) and plans == []


def test_calibrate_fills_the_closed_loop_defaults_it_was_not_given(monkeypatch):
    """The closed-loop options are None in the parser (to tell a typed one): a run gets ClosedLoopPlan's."""
    from pipelines.cli import main
    from pipelines.experiments.calibrate import ClosedLoopPlan

    plans = _episodes(monkeypatch)
    assert main([*CALIBRATE, "--dry-run", "--holdout-margins", "none"]) == 0
    assert plans == [ClosedLoopPlan("constant_velocity")]


@pytest.mark.parametrize("held", ["none", "conformal:0.3"], ids=["stored-after", "stored-first-put-back"])
def test_an_interrupted_held_out_run_leaves_the_calibrations_as_they_were(
    held, tmp_path, monkeypatch, capsys
):
    """The blocks were stored before the held-out episodes: Ctrl-C during them (rc 130) had already replaced
    the user's earlier block. They are stored after them, or, when the held-out episodes plan with them,
    before them and the earlier file is put back."""
    from pipelines.cli import main
    from pipelines.experiments import calibrate as experiment

    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path))
    path = tmp_path / "calibrations.json"
    _episodes(monkeypatch)
    assert main([*CALIBRATE, "--alpha", "0.3"]) == 0
    earlier = path.read_bytes()
    calibrate = experiment.closed_loop_errors
    during = []

    def interrupted(plan, progress=True, check_weights=None):
        if plan.seed == 7 + 200:  # the held-out episodes, after the calibration's
            during.append(path.read_bytes())
            raise KeyboardInterrupt
        return calibrate(plan, progress, check_weights)

    monkeypatch.setattr(experiment, "closed_loop_errors", interrupted)
    argv = [*CALIBRATE, "--alpha", "0.3", "--seed", "7", "--holdout"]  # other seeds: another block
    assert main([*argv, "--holdout-margins", held]) == 130
    assert path.read_bytes() == earlier
    assert (during[0] != earlier) == (held != "none")  # planned with the new block, so stored first
    if held != "none":
        assert (
            f"the held-out run did not finish: its blocks are taken out of {path}, the earlier ones put back"
            in capsys.readouterr().out
        )


@pytest.mark.parametrize("had_file", [True, False], ids=["earlier-file", "no-file"])
def test_taking_back_the_held_out_runs_blocks_keeps_a_block_another_calibrate_stored(
    had_file, tmp_path, monkeypatch
):
    """The whole earlier file was written back when the held-out run stopped: a block another calibrate
    stored in the same zoo meanwhile (here alpha 0.2, while this run's held-out episodes ran) was lost. Only
    this run's blocks are taken back now; with no earlier file, the file holds the other block alone."""
    from pipelines.cli import main
    from pipelines.experiments import calibrate as experiment
    from predictors.calibration_store import read_calibration_file, save_calibration

    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path))
    path = tmp_path / "calibrations.json"
    _episodes(monkeypatch)
    if had_file:
        assert main([*CALIBRATE, "--alpha", "0.3"]) == 0
    earlier = read_calibration_file(path) if had_file else []
    calibrate = experiment.closed_loop_errors

    def interrupted(plan, progress=True, check_weights=None):
        if plan.seed == 7 + 200:  # the held-out episodes: another calibrate stores its block now
            ours = read_calibration_file(path)
            save_calibration(dataclasses.replace(ours[-1], alpha=0.2))
            raise KeyboardInterrupt
        return calibrate(plan, progress, check_weights)

    monkeypatch.setattr(experiment, "closed_loop_errors", interrupted)
    argv = [*CALIBRATE, "--alpha", "0.3", "--seed", "7", "--holdout", "--holdout-margins", "conformal:0.3"]
    assert main(argv) == 130
    after = read_calibration_file(path)
    assert [b.alpha for b in after] == ([0.2, 0.3] if had_file else [0.2])
    assert [b.to_json() for b in after if b.alpha == 0.3] == [b.to_json() for b in earlier]


def test_a_block_whose_details_hold_a_tuple_is_taken_back_when_the_held_out_run_stops(tmp_path, monkeypatch):
    """closed_loop_errors' details come from asdict(plan), which keeps the plan's humans a tuple; the block
    read back from the file has a list there, so the stored block was never recognised as this run's: an
    interrupted held-out run left it in force (no earlier file: the file stayed) and said it was taken out."""
    from pipelines.cli import main
    from pipelines.experiments import calibrate as experiment
    from tests.calibration_blocks import class_errors

    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path))

    def measured(plan, progress=True, check_weights=None):
        if plan.margins.mode != "none":  # the held-out episodes, planning with the stored block
            assert (tmp_path / "calibrations.json").exists()
            raise KeyboardInterrupt
        scores, motion = class_errors(4)
        return experiment.ClosedLoopErrors(scores, motion, scores, {"humans": plan.humans}, None)

    monkeypatch.setattr(experiment, "closed_loop_errors", measured)
    argv = [
        *CALIBRATE,
        "--alpha",
        "0.3",
        "--humans",
        "5,6",
        "--holdout",
        "--holdout-margins",
        "conformal:0.3",
    ]
    assert main(argv) == 130
    assert not (tmp_path / "calibrations.json").exists()


def test_the_blocks_of_a_calibrate_killed_in_its_held_out_run_are_taken_back_by_the_next(
    tmp_path, monkeypatch, capsys
):
    """A calibrate killed (kill -9) during held-out episodes that planned with its new blocks left them in
    force for good: only Ctrl-C put the earlier ones back. The journal it wrote before storing them lets the
    next calibrate take them back."""
    from pipelines.cli import main
    from predictors.calibration_store import read_calibration_file

    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path))
    path = tmp_path / "calibrations.json"
    _episodes(monkeypatch)
    assert main([*CALIBRATE, "--alpha", "0.3"]) == 0
    earlier = [b.to_json() for b in read_calibration_file(path)]
    # The calibrate to kill, in a process of its own with _episodes' synthetic errors: a fork of this process,
    # which has other threads by now, may deadlock in the child (Python 3.12+ warns: DeprecationWarning).
    script = (
        "import os, sys\n"
        "from pipelines.cli import main\n"
        "from pipelines.experiments import calibrate as experiment\n"
        "from tests.calibration_blocks import synthetic_closed_loop\n"
        "def killed(plan, progress=True, check_weights=None):\n"
        "    if plan.seed == 7 + 200:  # the held-out episodes\n"
        "        os._exit(9)\n"
        "    return synthetic_closed_loop(plan)\n"
        "experiment.closed_loop_errors = killed\n"
        "sys.exit(main(sys.argv[1:]))\n"
    )
    argv = [*CALIBRATE, "--alpha", "0.3", "--seed", "7", "--holdout", "--holdout-margins", "conformal:0.3"]
    child = subprocess.Popen([sys.executable, "-c", script, *argv], cwd=REPO, stderr=subprocess.PIPE)
    _, err = child.communicate(timeout=300)
    assert child.returncode == 9, err
    pid = child.pid
    assert [b.to_json() for b in read_calibration_file(path)] != earlier  # the killed run's block in force
    capsys.readouterr()
    unfinished = tmp_path / f".calibrate-holdout.{pid}.json.tmp"  # as one killed while writing its journal
    unfinished.write_text('{"stored": [')
    assert main([*CALIBRATE, "--alpha", "0.2"]) == 0
    assert f"a calibrate killed during its held-out run (pid {pid}) did not finish" in capsys.readouterr().out
    assert [b.to_json() for b in read_calibration_file(path) if b.alpha == 0.3] == earlier
    assert not list(tmp_path.glob(".calibrate-holdout.*"))


def _killed_runs_journal(tmp_path, monkeypatch):
    """A user zoo in ``tmp_path`` whose calibrations file holds the block of a calibrate killed during its
    held-out run, over no earlier file, and the journal it left under this process's PID: (file, journal,
    block)."""
    from pipelines.cli import main
    from predictors.calibration_store import read_calibration_file

    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path))
    path = tmp_path / "calibrations.json"
    _episodes(monkeypatch)
    assert main([*CALIBRATE, "--alpha", "0.3"]) == 0
    (block,) = read_calibration_file(path)
    journal = tmp_path / f".calibrate-holdout.{os.getpid()}.json"
    journal.write_text(json.dumps({"stored": [block.to_json()], "earlier": None}))
    return path, journal, block


def test_a_killed_calibrates_journal_under_this_runs_own_pid_is_taken_back(tmp_path, monkeypatch, capsys):
    """In a container every run is PID 1: the journal a killed calibrate left had the next one's PID, which
    is alive (it is that very run), so its block stayed in force and the new run's journal replaced it."""
    from pipelines.cli import main
    from predictors.calibration_store import read_calibration_file

    path, journal, _ = _killed_runs_journal(tmp_path, monkeypatch)
    capsys.readouterr()
    assert main([*CALIBRATE, "--alpha", "0.2"]) == 0
    assert f"(pid {os.getpid()}) did not finish" in capsys.readouterr().out
    assert [b.alpha for b in read_calibration_file(path)] == [0.2]
    assert not journal.exists()


def test_runs_planning_with_calibrated_margins_take_a_killed_calibrates_blocks_back_first(
    tmp_path, monkeypatch, capsys
):
    """simulate and sweep planned with the blocks a calibrate killed during its held-out run had stored, and
    `zoo calibrations` listed them in force, until the next calibrate took them back."""
    from pipelines.cli import main
    from pipelines.commands.calibrate_store import take_back_before_planning
    from predictors.calibration_store import read_calibration_file

    path, journal, block = _killed_runs_journal(tmp_path, monkeypatch)
    take_back_before_planning([parse_margins("none"), parse_margins("fixed:0.1,0.1,0.1,0.1")])
    assert journal.exists() and read_calibration_file(path) == [block]  # no calibrated margins: untouched
    take_back_before_planning([parse_margins("none"), parse_margins("conformal-motion:0.3")])
    assert not journal.exists() and not path.exists()
    journal.write_text(json.dumps({"stored": [block.to_json()], "earlier": None}))
    path.write_text(
        json.dumps({"format": "crowdmpc-calibrations", "version": 1, "calibrations": [block.to_json()]})
    )
    capsys.readouterr()
    assert main(["zoo", "calibrations", "--predictor", "constant_velocity"]) == 0
    out = capsys.readouterr().out
    assert f"(pid {os.getpid()}) did not finish" in out and "user" not in out.split("did not finish")[1]
    assert not journal.exists()


def test_a_dry_run_holding_out_with_calibrated_margins_takes_a_killed_calibrates_blocks_back_first(
    tmp_path, monkeypatch, capsys
):
    """calibrate --dry-run took nothing back (it stores nothing), so its held-out episodes planned with the
    block a calibrate killed during its held-out run had left in force, and printed their coverage."""
    from pipelines.cli import main

    path, journal, _ = _killed_runs_journal(tmp_path, monkeypatch)
    capsys.readouterr()
    argv = [*CALIBRATE, "--alpha", "0.2", "--holdout", "--holdout-margins", "conformal:0.3", "--dry-run"]
    assert main(argv) == 2  # the killed run's block at 0.3 taken back, none is left to plan with
    captured = capsys.readouterr()
    assert f"(pid {os.getpid()}) did not finish" in captured.out
    assert "no closed-loop calibration at alpha=0.3" in captured.err
    assert not journal.exists() and not path.exists()


def test_an_unreadable_journal_of_a_killed_calibrate_is_one_line_naming_it(tmp_path, monkeypatch, capsys):
    from pipelines.cli import main

    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path))
    _episodes(monkeypatch)
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    pid = gone.pid  # a pid no process has now
    journal = tmp_path / f".calibrate-holdout.{pid}.json"
    journal.write_text('{"stored": [')
    assert main([*CALIBRATE, "--alpha", "0.2"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"crowdmpc calibrate: error: {journal}: a killed calibrate's record")
    assert "\n" not in err
    assert not (tmp_path / "calibrations.json").exists()


@pytest.mark.parametrize("given", [None, 3, ["none"]])
def test_margins_that_are_no_text_are_named(given):
    """None failed with "'NoneType' object has no attribute 'strip'"."""
    with pytest.raises(PipelineError, match=r"^margins must be text such as 'none' or 'conformal:0.1', got "):
        parse_margins(given)


def test_held_out_episodes_that_met_no_human_report_no_coverage_and_keep_the_block(
    tmp_path, monkeypatch, capsys
):
    """No human came within --near of a robot in the held-out episodes: the block was stored, then the
    command failed on "errors must have shape (n, H) with H >= 1, got (0, 0)", its --json unwritten."""
    import json

    from pipelines.cli import main
    from pipelines.experiments import calibrate as experiment
    from tests.calibration_blocks import synthetic_closed_loop

    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path))
    runs = iter([None, np.zeros((0, 0))])  # the calibration's errors, then the held-out run's: none

    def measured(plan, progress=True, check_weights=None):
        return synthetic_closed_loop(plan, next(runs))

    monkeypatch.setattr(experiment, "closed_loop_errors", measured)
    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path / "zoo"))
    out = tmp_path / "calibrate.json"
    assert main([*CALIBRATE, "--holdout", "--json", str(out)]) == 0
    said = capsys.readouterr().out
    assert "held-out: 0 samples (no human came within --near of a robot: no coverage)" in said
    written = json.loads(out.read_text())
    assert written["holdout_coverage"] is None and written["holdout_rows"] == 0
    assert (tmp_path / "zoo" / "calibrations.json").is_file()


def test_a_record_of_margins_made_behind_a_sensor_says_whether_its_tracker_gave_track_lengths():
    """Blocks made behind one range with and without track lengths stand side by side (Calibration.key):
    the record named the range alone, which both share."""
    from predictors.calibration_store import find_calibration, save_calibration

    shipped = find_calibration("constant_velocity", "closed-loop", 0.1)
    untracked = {**shipped.details, "sensor_range": 3.0, "sensor_tracks": False}
    save_calibration(dataclasses.replace(shipped, details=untracked))
    spec = MarginSpec("conformal", alpha=0.1, source="closed-loop")
    made = spec.behind(3.0, sensor_tracks=False).calibration("constant_velocity", None)
    assert made is not None and (made["sensor_range"], made["sensor_tracks"], made["zoo"]) == (
        3.0,
        False,
        "user",
    )
    assert "sensor_tracks" not in (spec.calibration("constant_velocity", None) or {})  # every human in view
